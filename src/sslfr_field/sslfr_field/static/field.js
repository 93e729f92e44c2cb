'use strict';
// The field page: polls /api/field once a second and renders one row per collector;
// commands (stow / auto, one collector or all) go to /api/command with the CSRF token.
let csrf = null;

function el(tag, text, cls) {
  const e = document.createElement(tag);
  if (text !== undefined && text !== null) e.textContent = String(text);
  if (cls) e.className = cls;
  return e;
}

function deg(rad) { return rad === null || rad === undefined ? '-' : (rad * 180 / Math.PI).toFixed(2); }

function say(text) { document.getElementById('message').textContent = text; }

async function command(name, collector, body) {
  const r = await fetch('/api/command/' + name, {
    method: 'POST', headers: {'Content-Type': 'application/json', 'X-CSRF-Token': csrf || ''},
    body: JSON.stringify(Object.assign({collector: collector}, body || {}))});
  const j = await r.json().catch(() => ({message: 'HTTP ' + r.status}));
  say((j.summary || name) + ' (' + collector + '): ' + (j.message || ''));
}

function render(data) {
  const body = document.querySelector('#field tbody');
  body.replaceChildren();
  for (const c of data.collectors) {
    const tr = el('tr');
    tr.id = 'collector-' + c.id;
    const name = el('td');
    if (c.page) { const a = el('a', c.id); a.href = c.page; a.target = '_blank'; a.rel = 'noopener'; name.append(a); }
    else name.textContent = c.id;
    name.append(el('div', c.namespace));
    tr.append(name);
    tr.append(el('td', c.link + (c.last_heard_s !== null ? ' (' + c.last_heard_s.toFixed(1) + ' s)' : ''), c.link));
    // phase (1 Hz) and safety state (10 Hz) older than 3 s: that process is not heard (its last values shown)
    const silent = (age, who) => age !== null && age > 3 ? ' (' + who + ' silent ' + age.toFixed(0) + ' s)' : '';
    tr.append(el('td', (c.phase || '-') + ' / ' + (c.mode || '-') + silent(c.phase_age_s, 'planner')));
    const safety = el('td', (c.safety_level || '-') + silent(c.safety_age_s, 'safety'), 'level-' + c.safety_level);
    if (c.safety_reasons.length) safety.append(el('div', c.safety_reasons.join('; ')));
    tr.append(safety);
    tr.append(el('td', Object.entries(c.axes).map(([a, s]) => a + ' ' + deg(s.error) + ' (' + s.state + ')').join(', ') || '-'));
    tr.append(el('td', Object.entries(c.temperatures).map(([k, v]) => k + ' ' + (v === null ? '-' : v.toFixed(1))).join(', ') || '-'));
    tr.append(el('td', c.beam === null ? '-' : c.beam.toFixed(0)));
    // where a flow meter counts (else '-'): flow [m^3/s] shown in L/h
    tr.append(el('td', c.flow === null ? '-' : (c.flow * 3.6e6).toFixed(1) + ' L/h, ' +
      (c.thermal_power === null ? '-' : c.thermal_power.toFixed(0) + ' W'), 'thermal'));
    const e = c.energy_today;
    tr.append(el('td', (e.absorbed_kwh === null ? '-' : 'absorbed ' + e.absorbed_kwh.toFixed(3)) +
      (e.thermal_kwh === null ? '' : ', thermal ' + e.thermal_kwh.toFixed(3)), 'energy'));
    const cmds = el('td');
    for (const [label, name, extra] of [['Stow', 'stow', null], ['Auto', 'mode', {mode: 'auto'}]]) {
      const b = el('button', label);
      b.disabled = !csrf;
      b.className = 'cmd-' + label.toLowerCase();
      b.addEventListener('click', () => command(name, c.id, extra));
      cmds.append(b);
    }
    tr.append(cmds);
    body.append(tr);
  }
  const l = data.links;
  document.getElementById('summary').textContent = data.collectors.length + ' collectors: ' +
    Object.entries(l).map(([k, v]) => v + ' ' + k).join(', ');
}

async function poll() {
  try {
    const r = await fetch('/api/field');
    if (r.ok) render(await r.json());
    else say('field: ' + ((await r.json()).message || r.status));
  } catch (e) { say('station not reachable'); }
}

async function session() {
  const j = await (await fetch('/api/session')).json();
  csrf = j.logged_in ? j.csrf : null;
  document.getElementById('login').hidden = !!csrf;
  document.getElementById('logout').hidden = !csrf;
  document.getElementById('stow-all').disabled = !csrf;
  document.getElementById('auto-all').disabled = !csrf;
  if (!j.password_set) say(j.problem);
}

document.getElementById('login').addEventListener('submit', async (ev) => {
  ev.preventDefault();
  const r = await fetch('/api/login', {method: 'POST', headers: {'Content-Type': 'application/json'},
    body: JSON.stringify({password: document.getElementById('password').value})});
  const j = await r.json();
  say(j.message);
  await session();
  poll();
});
document.getElementById('logout').addEventListener('click', async () => {
  await fetch('/api/logout', {method: 'POST', headers: {'X-CSRF-Token': csrf || ''}});
  await session();
  poll();
});
document.getElementById('stow-all').addEventListener('click', () => command('stow', 'all'));
document.getElementById('auto-all').addEventListener('click', () => command('mode', 'all', {mode: 'auto'}));
session().then(poll);
setInterval(poll, 1000);
