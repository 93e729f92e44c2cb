// The SSLFR operator page. Plain JavaScript, no library, nothing from the internet.
// Live state arrives by Server-Sent Events (/api/events); commands are POSTs with the
// session's CSRF token. Angles arrive in radians (REP-103) and are shown in degrees.
'use strict';

// The contract's movements; the page shows those of the collector description the
// planner names (info.collector.joints) once it is known.
const ALL_AXES = ['mirrors', 'mobile_structure', 'secondary_reflector'];
const joints = (s) => (s && s.info && s.info.collector && s.info.collector.joints) || ALL_AXES;
const SVGNS = 'http://www.w3.org/2000/svg';
const STALE_S = 3.0;                  // a value older than this [s wall] is greyed out
const $ = (id) => document.getElementById(id);
const deg = (r, n = 3) => (r === null || r === undefined) ? '–' : (r * 180 / Math.PI).toFixed(n) + '°';
const fix = (v, n = 1, unit = '') => (v === null || v === undefined) ? '–' : v.toFixed(n) + unit;

const page = { csrf: null, loggedIn: false, last: null, history: null, plotDue: 0, es: null };
// For tests and measurements: wall time each state event arrived and what it carried.
window.sslfrLog = [];

function utc(t) {
  if (!t) return '–';
  const d = new Date(t * 1000);
  const hh = (x) => String(x).padStart(2, '0');
  return `${hh(d.getUTCHours())}:${hh(d.getUTCMinutes())}:${hh(d.getUTCSeconds())} UTC ` +
    `(${d.toLocaleTimeString([], { hour: '2-digit', minute: '2-digit' })})`;
}

function setText(id, text, stale) {
  const el = $(id);
  if (!el) return;
  el.textContent = text;
  el.classList.toggle('stale-value', !!stale);
}

function el(tag, attrs, parent) {
  const e = document.createElementNS(SVGNS, tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (parent) parent.appendChild(e);
  return e;
}

// ------------------------------------------------------------------ live view
function render(s) {
  page.last = s;
  window.sslfrLog.push({ at: Date.now(), server_time: s.server_time, phase: s.phase && s.phase.name,
    beam: s.beam && s.beam.beam, mirrors: s.axes && s.axes.mirrors && s.axes.mirrors.measured });
  if (window.sslfrLog.length > 2000) window.sslfrLog.splice(0, 1000);
  const age = (k) => (s.ages && k in s.ages) ? s.ages[k] : Infinity;
  const p = s.phase;
  if (p) {
    setText('phase-name', p.name, age('phase') > STALE_S);
    setText('mode', 'mode ' + p.mode);
    setText('phase-reason', p.reason);
    setText('sunrise', utc(p.sunrise)); setText('noon', utc(p.noon)); setText('sunset', utc(p.sunset));
    const st = p.site || {};
    setText('site', `${fix(st.latitude, 5)}°, ${fix(st.longitude, 5)}°, ${fix(st.altitude, 0)} m (${st.source || '?'})`);
  }
  if (s.ros_time) setText('clock', 'tracker time ' + utc(s.ros_time));
  const g = s.gps;
  if (g) setText('gps', `${g.name}${g.horizontal_std !== null ? ', ±' + g.horizontal_std.toFixed(1) + ' m' : ''}` +
    (g.latitude !== null ? ` at ${g.latitude.toFixed(5)}°, ${g.longitude.toFixed(5)}°` : ''), age('gps') > STALE_S);
  renderSafety(s.safety, age('safety'));
  const sun = s.sun;
  if (sun) {
    const st = age('sun') > STALE_S;
    setText('sun-elevation', deg(sun.elevation, 2) + (sun.above_horizon ? '' : ' (below the horizon)'), st);
    setText('sun-azimuth', deg(sun.azimuth, 2), st);
    setText('sun-transversal', deg(sun.transversal, 2), st);
    setText('sun-longitudinal', deg(sun.longitudinal, 2), st);
  }
  renderAxes(s, age);
  const lim = s.info && s.info.temperature_limit;
  setText('temp-limit', lim ? lim.toFixed(1) + ' °C' : 'unknown (safety node not answering)');
  for (const name of ['inlet', 'outlet']) {
    const t = (s.temperatures || {})[name];
    const v = t ? t.value : null;
    setText(name, v === null ? (t ? 'invalid' : '–') : v.toFixed(1) + ' °C', age('temperatures/' + name) > STALE_S);
    const bar = $(name + '-bar');
    const top = lim || 150;
    bar.style.width = v === null ? '0' : Math.max(0, Math.min(100, 100 * v / top)) + '%';
    bar.classList.toggle('hot', v !== null && v >= top);
  }
  const b = s.beam;
  if (b) setText('beam', fix(b.beam, 0, ' W/m²') + (b.saturated ? ' (sensor saturated: at least)' : '') +
    ` from ${fix(b.illuminance, 0, ' lx')}`, age('beam') > STALE_S);
  const w = s.wind;
  if (w) setText('wind', `${fix(w.speed, 1, ' m/s')} (gust ${fix(w.gust, 1, ' m/s')}, mean ` +
    `${fix(w.mean, 1, ' m/s')} over ${fix(w.window / 60, 1, ' min')})`, age('wind') > STALE_S);
  const th = s.thermal;          // a collector with a flow meter only
  $('thermal-row').hidden = !th;
  if (th) setText('thermal', `${fix(th.power, 0, ' W')} at ${fix(th.lph, 1, ' L/h')}, efficiency ` +
    (th.efficiency === null ? '– (no beam)' : fix(100 * th.efficiency, 1, ' %')), age('thermal') > STALE_S);
  drawSouth(s); drawSide(s);
}

function duration(s) {
  const m = Math.floor(s / 60), r = Math.round(s - 60 * m);
  return m ? `${m} min ${r} s` : `${r} s`;
}

function renderSafety(sf, age) {
  const box = $('safety');
  if (!sf) return;
  box.className = 'banner level-' + sf.name;
  setText('safety-level', sf.name + (sf.stow_required ? ' (stow required)' : ''), age > STALE_S);
  setText('safety-since', sf.since ? 'since ' + utc(sf.since) : '');
  setText('safety-stopped', sf.stopped_axes.length ? 'stopped: ' + sf.stopped_axes.join(', ') : '');
  const wr = sf.wind_release;
  setText('safety-wind', !wr ? '' : (sf.wind_stow ? 'wind stow (face-up)' : 'wind stow') + ': ' +
    (wr.calm ? 'releases in ' + duration(wr.release_in) + ' if the wind stays calm'
             : 'waiting for the mean wind to calm down'));
  const ul = $('safety-reasons');
  ul.textContent = '';
  for (const r of sf.reasons) {
    const li = document.createElement('li');
    li.textContent = r.text;
    const h = document.createElement('span');
    h.className = 'hint'; h.textContent = 'To clear: ' + r.hint;
    li.appendChild(h); ul.appendChild(li);
  }
}

function renderAxes(s, age) {
  const body = document.querySelector('#axes tbody');
  const axes = joints(s);
  for (const axis of ALL_AXES) {                  // a movement the collector lacks: no row
    const old = $('axis-' + axis);
    if (old && !axes.includes(axis)) old.remove();
  }
  renderJogAxes(axes);
  for (const axis of axes) {
    let row = $('axis-' + axis);
    if (!row) {
      row = document.createElement('tr'); row.id = 'axis-' + axis;
      for (const k of ['name', 'state', 'commanded', 'setpoint', 'measured', 'error', 'accuracy', 'link', 'frames', 'homed']) {
        const td = document.createElement('td'); td.id = `axis-${axis}-${k}`; row.appendChild(td);
      }
      body.appendChild(row);
      $(`axis-${axis}-name`).textContent = axis;
    }
    const a = (s.axes || {})[axis];
    if (!a) continue;
    const st = age('axes/' + axis) > STALE_S;
    setText(`axis-${axis}-state`, a.state, st);
    setText(`axis-${axis}-commanded`, deg(a.commanded), st);
    setText(`axis-${axis}-setpoint`, deg(a.setpoint), st);
    setText(`axis-${axis}-measured`, deg(a.measured), st);
    setText(`axis-${axis}-error`, deg(a.error), st);
    // the accuracy alarm: RMS error over the driver's window while tracking, and its optical loss
    const acc = (s.accuracy || {})[axis] || {};
    const accText = acc.tracking ? `${acc.level} ${acc.error_rms_deg}\u00b0 RMS` +
      (acc.level !== 'OK' && acc.estimated_loss ? ` (${acc.estimated_loss})` : '') : 'not tracking';
    setText(`axis-${axis}-accuracy`, accText, st);
    $(`axis-${axis}-accuracy`).title = acc.message || '';
    $(`axis-${axis}-accuracy`).classList.toggle('bad', acc.level === 'ERROR');
    $(`axis-${axis}-accuracy`).classList.toggle('warn', acc.level === 'WARN');
    setText(`axis-${axis}-link`, a.link, st);
    $(`axis-${axis}-link`).classList.toggle('bad', a.link !== 'LINK_UP');
    setText(`axis-${axis}-frames`, `${a.frames_lost} / ${a.frames_bad}`, st);
    setText(`axis-${axis}-homed`, a.homed ? 'yes' : 'NO', st);
  }
}

function renderJogAxes(axes) {
  const sel = $('jog-axis');
  if (!sel || sel.dataset.axes === axes.join(',')) return;
  sel.dataset.axes = axes.join(',');
  const keep = sel.value;
  sel.textContent = '';
  for (const a of axes) {
    const o = document.createElement('option'); o.textContent = a; sel.appendChild(o);
  }
  if (axes.includes(keep)) sel.value = keep;
}

// ------------------------------------------------------------------ drawings
// View from the south: x to the right = east, so a mirror at x_i (west positive)
// is drawn at -x_i; a mirror angle beta (counter-clockwise seen from the south,
// positive = normal leaning west) turns the line counter-clockwise on screen.
// The lines: the collector description's (info.collector: positions x_i and each
// line's offset from the drive under its law), else the planner's geometry with seed
// 000's offsets psi_i / 2 (eqs. 11-14).
function geometry(s) {
  const i = s.info || {};
  const c = i.collector;
  if (c && c.lines) return { lines: c.lines, w: c.line_width, f: c.aim_height, tilting: c.tilting, name: c.name };
  const n = i.n_per_side ?? 12, w = i.mirror_width ?? 0.06, d = i.gap ?? 0.024;
  const f = (i.receiver_height ?? 1.5), central = i.central_mirror ?? true, pitch = w + d;
  const lines = [];
  for (let k = -n; k <= n; k++) {
    if (k === 0 && !central) continue;
    const x = central ? k * pitch : (k - Math.sign(k) * 0.5) * pitch;
    lines.push({ x, offset: -Math.atan(x / f) / 2 });
  }
  return { lines, w, f, tilting: true, name: null };
}

function drawSouth(s) {
  const svg = $('view-south');
  const g = geometry(s);
  const a = (s.axes || {}).mirrors;
  const beta0 = a ? a.measured : null;
  const xs = g.lines.map((l) => l.x);
  const pitch = xs.length > 1 ? Math.abs(xs[1] - xs[0]) : g.w;
  const span = Math.max(...xs.map(Math.abs)) + pitch;
  const scale = 1.45 / Math.max(span, g.f * 0.9);
  svg.textContent = '';
  const root = el('g', { transform: `scale(${scale})` }, svg);
  const sw = 0.012 / scale;
  el('line', { x1: -span, y1: 0.02 / scale, x2: span, y2: 0.02 / scale, stroke: '#8b7355', 'stroke-width': sw * 2 }, root);
  el('circle', { cx: 0, cy: -g.f, r: Math.max(0.025, 0.03 / scale), fill: '#111', id: 'south-receiver' }, root);
  el('text', { x: -span, y: -g.f, 'font-size': 0.09 / scale, fill: '#555' }, root).textContent = 'W';
  el('text', { x: span - 0.08 / scale, y: -g.f, 'font-size': 0.09 / scale, fill: '#555' }, root).textContent = 'E';
  if (g.name) el('text', { x: -span, y: 0.12 / scale, 'font-size': 0.07 / scale, fill: '#555', id: 'south-name' }, root).textContent = g.name;
  const sun = s.sun;
  if (sun && sun.transversal !== null) {
    const th = sun.transversal;               // positive toward the west (screen left)
    const dx = -Math.sin(th), dy = -Math.cos(th);
    const L = g.f * 1.25;
    el('line', { x1: dx * L, y1: dy * L, x2: 0, y2: 0, stroke: sun.above_horizon ? '#f59e0b' : '#9ca3af',
      'stroke-width': sw, 'stroke-dasharray': sun.above_horizon ? '' : `${3 * sw}`, id: 'south-sun' }, root);
    el('circle', { cx: dx * L, cy: dy * L, r: 0.06 / scale, fill: sun.above_horizon ? '#fbbf24' : '#d1d5db' }, root);
  }
  if (beta0 === null) return;
  let near = g.lines[0];                      // the line nearest the axis: its reflected ray is drawn
  for (const l of g.lines) {
    if (Math.abs(l.x) < Math.abs(near.x)) near = l;
    const b = beta0 + l.offset;
    const cx = -l.x, hx = Math.cos(b) * g.w / 2, hy = Math.sin(b) * g.w / 2;
    el('line', { x1: cx - hx, y1: hy, x2: cx + hx, y2: -hy, stroke: '#1e3a8a', 'stroke-width': sw * 1.6,
      class: 'mirror', 'data-angle': b.toFixed(6), 'data-x': l.x.toFixed(4) }, root);
  }
  if (sun && sun.above_horizon && sun.transversal !== null) {   // that line's reflected ray
    const th = sun.transversal, b = beta0 + near.offset;
    const din = [Math.sin(th), -Math.cos(th)];                   // toward the mirror (x east, y up)
    const nrm = [-Math.sin(b), Math.cos(b)];
    const dot = din[0] * nrm[0] + din[1] * nrm[1];
    const r = [din[0] - 2 * dot * nrm[0], din[1] - 2 * dot * nrm[1]];
    const L = r[1] > 0 ? g.f / r[1] : g.f;
    el('line', { x1: -near.x, y1: 0, x2: -near.x + r[0] * L, y2: -r[1] * L, stroke: '#dc2626', 'stroke-width': sw * 0.8,
      id: 'south-reflection' }, root);
  }
}

// View from the east: the collector's south end (+p) on the left. beta_M / beta_a > 0
// lower the south end; theta_l > 0 puts the sun toward the south end.
function drawSide(s) {
  const svg = $('view-side');
  const g = geometry(s);
  const len = 0.75, y0 = -0.25;
  svg.textContent = '';
  const root = el('g', {}, svg);
  const sw = 0.012;
  el('line', { x1: -1.5, y1: 0.22, x2: 1.5, y2: 0.22, stroke: '#8b7355', 'stroke-width': sw * 2 }, root);
  el('text', { x: -1.5, y: 0.2, 'font-size': 0.09, fill: '#555' }, root).textContent = 'S end';
  el('text', { x: 1.25, y: 0.2, 'font-size': 0.09, fill: '#555' }, root).textContent = 'N end';
  const axes = s.axes || {};
  const h = 1.2;
  const seg = (b, y, color, id) => {
    if (b === null || b === undefined) return;
    el('line', { x1: -len * Math.cos(b), y1: y0 + y + len * Math.sin(b), x2: len * Math.cos(b), y2: y0 + y - len * Math.sin(b),
      stroke: color, 'stroke-width': sw * 2, id, 'data-angle': b.toFixed(6) }, root);
  };
  const has = joints(s);
  if (has.includes('mobile_structure')) seg(axes.mobile_structure && axes.mobile_structure.measured, 0, '#1e3a8a', 'side-structure');
  else seg(0, 0, '#9ca3af', 'side-structure-fixed');          // rows fixed flat: no such movement
  if (has.includes('secondary_reflector')) seg(axes.secondary_reflector && axes.secondary_reflector.measured, -h, '#111', 'side-reflector');
  else seg(0, -h, '#9ca3af', 'side-reflector-fixed');
  el('line', { x1: 0, y1: 0.22, x2: 0, y2: y0, stroke: '#6b7280', 'stroke-width': sw }, root);
  const sun = s.sun;
  if (sun && sun.longitudinal !== null) {
    const th = sun.longitudinal;
    const dx = -Math.sin(th), dy = -Math.cos(th), L = 1.5;
    el('line', { x1: dx * L, y1: y0 + dy * L, x2: 0, y2: y0, stroke: sun.above_horizon ? '#f59e0b' : '#9ca3af',
      'stroke-width': sw, id: 'side-sun' }, root);
    el('circle', { cx: dx * L, cy: y0 + dy * L, r: 0.06, fill: sun.above_horizon ? '#fbbf24' : '#d1d5db' }, root);
  }
}

// ------------------------------------------------------------------ plots
function plot(svg, t, series, opts) {
  const W = svg.viewBox.baseVal.width, H = svg.viewBox.baseVal.height, L = 48, R = 8, T = 8, B = 22;
  svg.textContent = '';
  let ys = [];
  for (const sr of series) ys = ys.concat(sr.y.filter((v) => v !== null));
  if (opts.hline) ys.push(opts.hline);
  if (!t.length || !ys.length) {
    el('text', { x: W / 2, y: H / 2, 'text-anchor': 'middle', fill: '#888', 'font-size': 13 }, svg).textContent = 'no data yet today';
    return;
  }
  let y0 = Math.min(...ys), y1 = Math.max(...ys);
  if (y1 - y0 < 1e-9) { y0 -= 1; y1 += 1; }
  const pad = (y1 - y0) * 0.05; y0 -= pad; y1 += pad;
  const t0 = t[0], t1 = Math.max(t[t.length - 1], t0 + 60);
  const X = (v) => L + (W - L - R) * (v - t0) / (t1 - t0);
  const Y = (v) => T + (H - T - B) * (1 - (v - y0) / (y1 - y0));
  el('rect', { x: L, y: T, width: W - L - R, height: H - T - B, fill: 'none', stroke: '#ccc' }, svg);
  for (let k = 0; k <= 4; k++) {
    const v = y0 + (y1 - y0) * k / 4;
    el('text', { x: L - 4, y: Y(v) + 4, 'text-anchor': 'end', 'font-size': 10, fill: '#555' }, svg).textContent = v.toFixed(Math.abs(y1 - y0) < 5 ? 2 : 0);
  }
  const hour = 3600, first = Math.ceil(t0 / hour) * hour;
  const stepH = Math.max(1, Math.ceil((t1 - t0) / hour / 8));
  for (let h = first; h <= t1; h += stepH * hour) {
    el('line', { x1: X(h), y1: T, x2: X(h), y2: H - B, stroke: '#eee' }, svg);
    el('text', { x: X(h), y: H - 6, 'text-anchor': 'middle', 'font-size': 10, fill: '#555' }, svg).textContent =
      String(new Date(h * 1000).getUTCHours()).padStart(2, '0') + ':00';
  }
  if (opts.hline) el('line', { x1: L, y1: Y(opts.hline), x2: W - R, y2: Y(opts.hline), stroke: '#dc2626', 'stroke-dasharray': '6 3' }, svg);
  for (const sr of series) {
    let d = '', pen = false;
    for (let k = 0; k < t.length; k++) {
      const v = sr.y[k];
      if (v === null || v === undefined) { pen = false; continue; }
      d += (pen ? 'L' : 'M') + X(t[k]).toFixed(1) + ',' + Y(v).toFixed(1);
      pen = true;
    }
    el('path', { d, fill: 'none', stroke: sr.color, 'stroke-width': 1.5, 'stroke-dasharray': sr.dash || '' }, svg);
  }
}

function drawPlots() {
  const h = page.history;
  if (!h) return;
  const c = h.columns, toDeg = (a) => a.map((v) => v === null ? null : v * 180 / Math.PI);
  const colors = { mirrors: '#1d4ed8', mobile_structure: '#059669', secondary_reflector: '#7c3aed' };
  const series = [];
  for (const a of joints(page.last)) {
    series.push({ y: toDeg(c[a + '_measured']), color: colors[a] });
    series.push({ y: toDeg(c[a + '_setpoint']), color: colors[a], dash: '5 3' });
  }
  series.push({ y: toDeg(c.mirrors_ideal), color: '#f59e0b', dash: '2 2' });
  plot($('plot-angles'), h.t, series, {});
  const lim = page.last && page.last.info && page.last.info.temperature_limit;
  plot($('plot-temps'), h.t, [{ y: c.inlet, color: '#2563eb' }, { y: c.outlet, color: '#dc2626' }], { hline: lim || 150 });
  plot($('plot-beam'), h.t, [{ y: c.beam, color: '#f59e0b' }], {});
}

function schedulePlots() {
  const now = Date.now();
  if (now >= page.plotDue) { page.plotDue = now + 2000; drawPlots(); }
}

async function loadHistory() {
  const r = await fetch('/api/history', { credentials: 'same-origin' });
  if (r.ok) { page.history = await r.json(); drawPlots(); }
}

function addSample(ev) {
  const h = page.history;
  if (!h || ev.day !== h.day) { loadHistory(); return; }
  h.t.push(ev.t);
  for (const [k, v] of Object.entries(ev.row)) (h.columns[k] = h.columns[k] || []).push(v);
  schedulePlots();
}

// ------------------------------------------------------------------ connection
function connect() {
  if (page.es) page.es.close();
  const es = new EventSource('/api/events');
  page.es = es;
  es.addEventListener('state', (e) => {
    setText('conn', 'live'); $('conn').className = 'badge live';
    render(JSON.parse(e.data));
  });
  es.addEventListener('sample', (e) => addSample(JSON.parse(e.data)));
  es.onerror = () => { setText('conn', 'reconnecting'); $('conn').className = 'badge stale'; };
}
setInterval(() => {            // no event for 3 s: the tracker is not being heard
  const last = window.sslfrLog[window.sslfrLog.length - 1];
  if (!last || Date.now() - last.at > 3000) { setText('conn', last ? 'no data' : 'connecting'); $('conn').className = 'badge stale'; }
}, 1000);

// ------------------------------------------------------------------ login and commands
async function session() {
  const r = await fetch('/api/session', { credentials: 'same-origin' });
  const s = await r.json();
  page.csrf = s.csrf; page.loggedIn = s.logged_in;
  $('login-form').hidden = s.logged_in;
  $('logout-btn').hidden = !s.logged_in;
  setText('login-state', s.logged_in ? 'Logged in: commands enabled.' :
    (s.password_set ? 'Log in with the operator password to send commands.' : s.problem));
  for (const b of document.querySelectorAll('#card-commands .buttons button')) b.disabled = !s.logged_in;
  return s;
}

function logResult(what, res) {
  const li = document.createElement('li');
  const ok = res.success === true;
  li.className = ok ? 'ok' : 'refused';
  li.textContent = `${new Date().toLocaleTimeString()} ${what}: ${ok ? 'done' : 'REFUSED'} — ${res.message || ''}`;
  const log = $('cmd-log');
  log.insertBefore(li, log.firstChild);
  while (log.children.length > 30) log.removeChild(log.lastChild);
  $('cmd-log').dataset.last = JSON.stringify({ what, success: ok, message: res.message || '' });
}

async function command(name, body, label) {
  let res;
  try {
    const r = await fetch('/api/command/' + name, {
      method: 'POST', credentials: 'same-origin',
      headers: { 'Content-Type': 'application/json', 'X-CSRF-Token': page.csrf || '' },
      body: JSON.stringify(body || {}) });
    res = await r.json();
    if (r.status === 401) await session();
  } catch (e) { res = { success: false, message: 'no answer from the tracker: ' + e }; }
  logResult(label || name, res);
  return res;
}

document.addEventListener('DOMContentLoaded', () => {
  $('login-form').addEventListener('submit', async (e) => {
    e.preventDefault();
    const r = await fetch('/api/login', { method: 'POST', credentials: 'same-origin',
      headers: { 'Content-Type': 'application/json' }, body: JSON.stringify({ password: $('login-password').value }) });
    const res = await r.json();
    $('login-password').value = '';
    logResult('login', res);
    await session();
  });
  $('logout-btn').addEventListener('click', async () => {
    await fetch('/api/logout', { method: 'POST', credentials: 'same-origin', headers: { 'X-CSRF-Token': page.csrf || '' } });
    await session();
  });
  for (const b of document.querySelectorAll('button[data-cmd]')) {
    b.addEventListener('click', () => {
      const body = b.dataset.mode ? { mode: b.dataset.mode } : {};
      command(b.dataset.cmd, body, b.textContent);
    });
  }
  const jog = (sign) => {
    const axis = $('jog-axis').value, d = parseFloat($('jog-deg').value);
    command('jog', { axis, delta: sign * d * Math.PI / 180 }, `jog ${axis} ${sign > 0 ? '+' : '−'}${d}°`);
  };
  $('jog-minus').addEventListener('click', () => jog(-1));
  $('jog-plus').addEventListener('click', () => jog(1));
  $('cmd-home').addEventListener('click', () => command('home', { axis: $('jog-axis').value }, 'home ' + $('jog-axis').value));
  session();
  loadHistory();
  loadBags();
  connect();
});

// ------------------------------------------------------------------ recorded days
function size(b) { return b > 1e9 ? (b / 1e9).toFixed(2) + ' GB' : (b / 1e6).toFixed(1) + ' MB'; }

async function loadBags() {
  const r = await fetch('/api/bags', { credentials: 'same-origin' });
  if (!r.ok) return;
  const j = await r.json();
  setText('bag-dir', j.bag_dir ? 'Bags in ' + j.bag_dir : (j.message || ''));
  const body = document.querySelector('#bags tbody');
  body.textContent = '';
  for (const b of j.bags) {
    const tr = document.createElement('tr');
    const cells = [b.date || b.name, b.start ? `${utc(b.start).slice(0, 8)} – ${utc(b.end).slice(0, 8)}` : (b.problem ? 'no metadata' : '–'),
      String(b.messages), size(b.size)];
    for (const c of cells) { const td = document.createElement('td'); td.textContent = c; tr.appendChild(td); }
    const td = document.createElement('td');
    const rep = document.createElement('button'); rep.textContent = 'report';
    rep.addEventListener('click', () => showReport(b.name, rep));
    const dl = document.createElement('a'); dl.textContent = ' download'; dl.href = `/api/bags/${encodeURIComponent(b.name)}/download`;
    td.appendChild(rep); td.appendChild(dl); tr.appendChild(td); tr.title = b.name + (b.problem ? ': ' + b.problem : '');
    body.appendChild(tr);
  }
}

async function showReport(name, button) {
  $('report').hidden = false;
  setText('report-title', 'Report of ' + name + ' (making it can take a minute)…');
  $('report-text').textContent = ''; $('report-plots').textContent = '';
  button.disabled = true;
  try {
    const r = await fetch(`/api/bags/${encodeURIComponent(name)}/report`, { credentials: 'same-origin' });
    const j = await r.json();
    setText('report-title', 'Report of ' + name);
    $('report-text').textContent = j.text || j.message;
    for (const p of j.plots || []) { const img = document.createElement('img'); img.src = p; img.alt = p; $('report-plots').appendChild(img); }
  } finally { button.disabled = false; }
}
