"""The operator page's HTTP application (aiohttp; no rclpy: the node hands it a
:class:`Backend`).

Routes (JSON unless said; *view* = open when ``open_view``, else login needed;
*command* = login + CSRF token):

=========================================  =====  ======================================
``GET /``, ``GET /static/<file>``           view   the page and its assets (all local)
``GET /api/state``                          view   live snapshot (:meth:`LiveState.snapshot`)
``GET /api/events``                         view   Server-Sent Events: ``state`` (at most
                                                   every ``push_period`` when changed),
                                                   ``sample`` (a new day-plot sample)
``GET /api/history``                        view   the day buffer (plots)
``GET /api/session``                        --     logged in?, CSRF token, password set?
``POST /api/login`` ``{"password"}``        --     rate-limited; sets the session cookie
``POST /api/logout``                        cmd    ends the session
``POST /api/command/<name>``                cmd    :mod:`.commands`; the service's answer
``GET /api/bags``                           view   recorded days
``GET /api/bags/<name>/report``             view   the day report (made once, cached)
``GET /api/bags/<name>/report/<file>.png``  view   its plots
``GET /api/bags/<name>/download``           view   the bag as a zip
=========================================  =====  ======================================

Security: the session cookie is HttpOnly and SameSite=Strict; a POST must carry the
session's CSRF token in ``X-CSRF-Token`` and, when the browser sends ``Origin`` or
``Sec-Fetch-Site``, come from this same origin; bodies above ``max_request_bytes`` are
refused (413) before they are read, bodies that are not JSON objects nested at most
``max_json_depth`` deep are refused (400), bodies slower than ``body_timeout`` (408);
every command, and every refused one, is logged with its origin (client address,
session) to the node's log and the audit file.

Hostile clients (:mod:`sslfr_common.netguard`, shared with every network face): caps
of connections per address and in all, header and idle time-outs (:class:`Server`),
caps of event streams per address and in all, logins counted before the password is
checked (:class:`~.auth.LoginLimiter`), and every refusal logged as one rate-limited
line (never a traceback). No request of any shape is answered 500: an unexpected
error is one logged line and a 500 only for a fault of the page itself.
"""
from __future__ import annotations

import asyncio
import datetime as dt
import json
import os
import sys
import threading
import time
from pathlib import Path
from sslfr_common.files import user_path
from typing import Any, Callable, Protocol

from aiohttp import web
from sslfr_common import netguard

from . import bags as bags_mod
from . import commands
from .auth import LoginLimiter, PasswordFile, SessionStore, verify_password
from .live import DayBuffer, LiveState

STATIC = Path(__file__).resolve().parent / 'static'
COOKIE = 'sslfr_session'
PUSHER = web.AppKey('pusher', asyncio.Task)
REPORT_TIMEOUT = 300.0
POLL = 0.05            # [s] how often the pusher looks for a change (a lone change waits <= this)
STREAM_WRITE_TIMEOUT = 10.0   # [s] an event stream whose client does not read for this long is closed
HASH_SLOTS = 2         # password checks (scrypt, ~16 MiB each) run at once at most
LOG_INTERVAL = 10.0    # [s] at most one line per kind of refusal per this long
AUDIT_REFUSALS_PER_S, AUDIT_BURST = 5.0, 200.0   # refusals written to the audit file (token bucket)


class SlowBody(commands.CommandError):
    """The request body did not arrive within ``body_timeout`` (HTTP 408)."""


def unlock_path(password_file: str | os.PathLike) -> Path:
    """The file ``./sslfr web-password --unlock`` writes: when it changes, the page
    ends every login lockout (only someone with a shell on the collector can)."""
    p = user_path(password_file)
    return p.with_name(p.name + '.unlock')


def _stamp(path: Path):
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_mtime_ns, st.st_size, st.st_ino)


def trusted_networks(cfg: dict) -> list:
    """Networks the global login limit never refuses (param ``login_trusted_networks``)."""
    text = str(cfg.get('login_trusted_networks', 'auto')).strip()
    nets = netguard.local_networks(str(cfg.get('bind_address', '127.0.0.1')))
    if text != 'auto':
        nets = nets[:2] + netguard.parse_networks(text)     # loopback always
    return nets


class Backend(Protocol):
    """What the app needs from the node (see sslfr_web.web_node)."""

    state: LiveState
    buffer: DayBuffer

    def ros_time(self) -> float | None: ...

    def jog_limits(self) -> dict[str, commands.JogLimits]: ...   # the collector's movements only

    def bag_dir(self) -> str | None: ...

    def site_config(self) -> str | None: ...

    async def call(self, cmd: commands.Command) -> dict: ...

    def log(self, level: str, text: str) -> None: ...


def _json(data: Any, status: int = 200) -> web.Response:
    return web.json_response(data, status=status, dumps=lambda d: json.dumps(d, allow_nan=False))


def _refuse(status: int, message: str, **extra) -> web.Response:
    return _json({'ok': False, 'success': False, 'message': message, **extra}, status)


class OperatorApp:
    """State of one running page: sessions, limiter, audit, broadcaster."""

    def __init__(self, cfg: dict, backend: Backend, clock: Callable[[], float] = time.monotonic):
        self.cfg, self.backend, self.clock = cfg, backend, clock
        self.passwords = PasswordFile(cfg['password_file'])
        self.sessions = SessionStore(timeout=float(cfg['session_timeout']), clock=clock)
        self.trusted = trusted_networks(cfg)
        self.limiter = LoginLimiter(int(cfg['login_max_failures']), float(cfg['login_window']), clock,
                                    lockout=float(cfg['login_lockout']), lockout_max=float(cfg['login_lockout_max']),
                                    trusted=lambda a: netguard.in_networks(a, self.trusted))
        self.audit_path = user_path(cfg['audit_file']) if cfg.get('audit_file') else None
        self.counters = {'commands': 0, 'commands_refused': 0, 'logins': 0, 'login_failures': 0,
                         'login_rate_limited': 0, 'events_sent': 0, 'clients': 0, 'bad_requests': 0,
                         'streams_evicted': 0, 'errors': 0, 'unlocks': 0}
        self.oneline = netguard.OneLineLog(lambda level, text: self.backend.log(level, text), LOG_INTERVAL, clock)
        self.guard = netguard.ConnectionGuard(netguard.limits_from(cfg), self.oneline)
        self.streams = netguard.StreamSlots(int(cfg['max_streams_per_address']), int(cfg['max_streams']))
        self._clients: set[asyncio.Queue] = set()
        self._report_lock = asyncio.Lock()
        self._hash_slots: asyncio.Semaphore | None = None
        self._audit_tokens, self._audit_t, self._audit_dropped = AUDIT_BURST, clock(), 0
        self._unlock_file = unlock_path(cfg['password_file'])
        self._unlock_stamp = _stamp(self._unlock_file)
        self._password_stamp = _stamp(self.passwords.path)

    # ------------------------------------------------------------------ helpers
    def origin(self, request: web.Request, session=None) -> str:
        fwd = request.remote or '?'
        sid = f' session {session.token[:6]}' if session else ''
        return f'{fwd}{sid}'

    def session_of(self, request: web.Request):
        return self.sessions.get(request.cookies.get(COOKIE))

    def can_view(self, request: web.Request) -> bool:
        return bool(self.cfg['open_view']) or self.session_of(request) is not None

    def audit(self, origin: str, what: str, request: Any, result: dict, level: str = 'info') -> None:
        line = {'time': dt.datetime.now(dt.timezone.utc).isoformat(timespec='milliseconds'),
                'ros_time': self.backend.ros_time(), 'origin': origin, 'command': what,
                'request': request, 'success': bool(result.get('success')), 'message': result.get('message', '')}
        text = (f'command {what} {json.dumps(request)} from {origin}: '
                f'{"done" if line["success"] else "refused"}: {line["message"]}')
        if line['success'] or level == 'info':
            self.backend.log(level, text)
        else:                    # refusals can come in floods: one line per kind per LOG_INTERVAL
            self.oneline.report('refused login' if what == 'login' else 'refused command', text, level)
        self._write_audit(line)

    def _audit_file(self, origin: str, what: str, request: Any, result: dict) -> None:
        self._write_audit({'time': dt.datetime.now(dt.timezone.utc).isoformat(timespec='milliseconds'),
                           'ros_time': self.backend.ros_time(), 'origin': origin, 'command': what,
                           'request': request, 'success': bool(result.get('success')),
                           'message': result.get('message', '')})

    def _write_audit(self, line: dict) -> None:
        """Append one line; refusals beyond :data:`AUDIT_REFUSALS_PER_S` (burst
        :data:`AUDIT_BURST`) are counted and summarised in the next line written, so a
        flood cannot fill the disk."""
        if self.audit_path is None:
            return
        now = self.clock()
        self._audit_tokens = min(AUDIT_BURST, self._audit_tokens + (now - self._audit_t) * AUDIT_REFUSALS_PER_S)
        self._audit_t = now
        if not line['success']:
            if self._audit_tokens < 1.0:
                self._audit_dropped += 1
                self.counters['audit_dropped'] = self.counters.get('audit_dropped', 0) + 1
                return
            self._audit_tokens -= 1.0
        if self._audit_dropped:
            line = {**line, 'refusals_not_written_before': self._audit_dropped}
            self._audit_dropped = 0
        try:
            self.audit_path.parent.mkdir(parents=True, exist_ok=True)
            with open(self.audit_path, 'a', encoding='utf-8') as fh:
                fh.write(json.dumps(line, allow_nan=False, default=str) + '\n')
        except (OSError, ValueError) as exc:
            self.oneline.report('audit file', f'audit file {self.audit_path}: {exc}', 'error')

    def _same_origin(self, request: web.Request) -> bool:
        site = request.headers.get('Sec-Fetch-Site')
        if site and site not in ('same-origin', 'none'):
            return False
        origin = request.headers.get('Origin')
        if origin and origin != 'null':
            return origin == f'{request.scheme}://{request.host}'
        return origin != 'null'

    async def _read_json(self, request: web.Request) -> dict:
        """The body as a JSON object ({} when empty), bounded in size, depth and time;
        :class:`commands.CommandError` (a 400 for the client) otherwise."""
        try:
            raw = await asyncio.wait_for(request.read(), float(self.cfg['body_timeout']))
        except asyncio.TimeoutError:
            raise SlowBody(f'the request body did not arrive within {self.cfg["body_timeout"]} s') from None
        return commands.parse_body(raw, max_bytes=int(self.cfg['max_request_bytes']),
                                   max_depth=int(self.cfg['max_json_depth']))

    def bad_request(self, request: web.Request, what: str, message: str, status: int = 400) -> web.Response:
        """Count, audit and answer a malformed request (one rate-limited log line)."""
        self.counters['bad_requests'] += 1
        self.oneline.report('bad request', f'{what} from {request.remote or "?"} refused: {message}')
        self._audit_file(self.origin(request), what, None, {'success': False, 'message': message})
        return _refuse(status, message)

    def refresh_unlock(self) -> None:
        """End every lockout when the unlock file or the password file changed."""
        unlock, pw = _stamp(self._unlock_file), _stamp(self.passwords.path)
        if unlock != self._unlock_stamp or pw != self._password_stamp:
            changed = 'unlock file' if unlock != self._unlock_stamp else 'password file'
            self._unlock_stamp, self._password_stamp = unlock, pw
            if self.limiter.locked() or changed == 'unlock file':
                self.limiter.clear()
                self.counters['unlocks'] += 1
                self.backend.log('warn', f'login lockouts ended: the {changed} changed')

    # ------------------------------------------------------------------ middleware
    @web.middleware
    async def middleware(self, request: web.Request, handler):
        self.guard.busy(request.transport)          # the head is in: no header/idle time-out now
        try:
            return await self._guarded(request, handler)
        finally:
            self.guard.idle(request.transport)

    async def _guarded(self, request: web.Request, handler):
        limit = int(self.cfg['max_request_bytes'])
        if request.content_length is not None and request.content_length > limit:
            return self.bad_request(request, request.path[:80], f'request body too large '
                                    f'({request.content_length} bytes > {limit})', 413)
        if request.method == 'POST' and not self._same_origin(request):
            self.audit(self.origin(request), request.path[:80], None,
                       {'success': False, 'message': 'refused: cross-site request'}, 'warn')
            return _refuse(403, 'refused: the request does not come from this page (cross-site)')
        try:
            resp = await handler(request)
        except web.HTTPRequestEntityTooLarge:
            resp = self.bad_request(request, request.path[:80], f'request body too large (> {limit} bytes)', 413)
        except web.HTTPException:
            raise
        except (ConnectionError, asyncio.CancelledError):
            raise
        except Exception as exc:  # noqa: BLE001 - one line, never a traceback per request
            self.counters['errors'] += 1
            self.oneline.report('internal error', f'{request.method} {request.path[:80]} from '
                                f'{request.remote or "?"}: {exc.__class__.__name__}: {exc}', 'error')
            resp = _refuse(500, f'internal error ({exc.__class__.__name__}); see the web node\'s log')
        resp.headers.setdefault('X-Content-Type-Options', 'nosniff')
        resp.headers.setdefault('Referrer-Policy', 'no-referrer')
        resp.headers.setdefault('X-Frame-Options', 'DENY')
        resp.headers.setdefault('Content-Security-Policy',
                                "default-src 'self'; img-src 'self' data:; style-src 'self'; "
                                "script-src 'self'; connect-src 'self'; frame-ancestors 'none'; base-uri 'none'")
        if request.path.startswith('/api/'):
            resp.headers.setdefault('Cache-Control', 'no-store')
        return resp

    # ------------------------------------------------------------------ page and live data
    async def index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / 'index.html', headers={'Cache-Control': 'no-cache'})

    async def static(self, request: web.Request) -> web.StreamResponse:
        name = request.match_info['name']
        allowed = {p.name for p in STATIC.iterdir() if p.is_file()}
        if name not in allowed:
            raise web.HTTPNotFound()
        return web.FileResponse(STATIC / name, headers={'Cache-Control': 'no-cache'})

    def _view_refused(self, request):
        if self.can_view(request):
            return None
        return _refuse(401, 'log in to see the tracker (open_view is off)')

    async def state(self, request: web.Request) -> web.Response:
        return self._view_refused(request) or _json(self.backend.state.snapshot(self.backend.ros_time()))

    async def history(self, request: web.Request) -> web.Response:
        return self._view_refused(request) or _json(self.backend.buffer.to_json())

    async def events(self, request: web.Request) -> web.StreamResponse:
        refused = self._view_refused(request)
        if refused:
            return refused
        resp = web.StreamResponse(headers={'Content-Type': 'text/event-stream', 'Cache-Control': 'no-store',
                                           'X-Accel-Buffering': 'no'})
        await resp.prepare(request)
        queue: asyncio.Queue = asyncio.Queue(maxsize=4)

        evicted = asyncio.Event()

        def evict():               # a newer stream took this one's slot (netguard.StreamSlots)
            self.counters['streams_evicted'] += 1
            evicted.set()
            while queue.full():
                queue.get_nowait()
            queue.put_nowait(None)
        slot = self.streams.acquire(request.remote or '?', evict)
        self._clients.add(queue)
        self.counters['clients'] = len(self._clients)
        write_timeout = STREAM_WRITE_TIMEOUT
        try:
            await asyncio.wait_for(resp.write(b'retry: 1000\n\n'), write_timeout)
            await asyncio.wait_for(resp.write(self._event('state', self.backend.state.snapshot(
                self.backend.ros_time()))), write_timeout)
            while True:
                try:
                    data = await asyncio.wait_for(queue.get(), 15.0)
                except asyncio.TimeoutError:
                    data = b': keep-alive\n\n'
                if data is None or evicted.is_set():
                    break
                await asyncio.wait_for(resp.write(data), write_timeout)
        except asyncio.TimeoutError:            # the client does not read: drop it
            if request.transport is not None:
                request.transport.abort()
        except (ConnectionResetError, asyncio.CancelledError, RuntimeError):
            pass
        finally:
            self.streams.release(slot)
            self._clients.discard(queue)
            self.counters['clients'] = len(self._clients)
        return resp

    @staticmethod
    def _event(name: str, data: Any) -> bytes:
        return f'event: {name}\ndata: {json.dumps(data, allow_nan=False, separators=(",", ":"))}\n\n'.encode()

    def _broadcast(self, data: bytes) -> None:
        for q in list(self._clients):
            if q.full():
                try:
                    q.get_nowait()          # a slow client gets the newest state, not a backlog
                except asyncio.QueueEmpty:
                    pass
            q.put_nowait(data)
            self.counters['events_sent'] += 1

    async def pusher(self) -> None:
        """Send the state to every connected page when it changed: within
        :data:`POLL` of a change, at most once per ``push_period``; a new day-plot
        sample as soon as it is taken."""
        last_state, last_buf = -1, self.backend.buffer.version
        period = float(self.cfg['push_period'])
        tick = min(POLL, period)
        loop = asyncio.get_running_loop()
        last_push = 0.0
        while True:
            await asyncio.sleep(tick)
            if not self._clients:
                continue
            st = self.backend.state
            if st.version != last_state and loop.time() - last_push >= period - 1e-3:
                last_state, last_push = st.version, loop.time()
                self._broadcast(self._event('state', st.snapshot(self.backend.ros_time())))
            buf = self.backend.buffer
            if buf.version != last_buf:
                last_buf = buf.version
                j = buf.to_json()
                if j['t']:
                    self._broadcast(self._event('sample', {'t': j['t'][-1], 'day': j['day'],
                                                           'row': {c: v[-1] for c, v in j['columns'].items()}}))

    # ------------------------------------------------------------------ login
    async def session_info(self, request: web.Request) -> web.Response:
        s = self.session_of(request)
        line = self.passwords.line()
        return _json({'logged_in': s is not None, 'csrf': s.csrf if s else None,
                      'password_set': line is not None, 'problem': self.passwords.problem,
                      'open_view': bool(self.cfg['open_view'])})

    def _rate_limited(self, addr: str, wait: float) -> web.Response:
        self.counters['login_rate_limited'] += 1
        self.audit(addr, 'login', None, {'success': False, 'message': f'rate limited ({wait:.0f} s)'}, 'warn')
        return _refuse(429, f'too many failed logins: try again in {wait:.0f} s', retry_after=round(wait, 1))

    async def login(self, request: web.Request) -> web.Response:
        addr = request.remote or '?'
        self.refresh_unlock()
        wait = self.limiter.retry_after(addr)
        if wait > 0:
            return self._rate_limited(addr, wait)
        try:
            body = await self._read_json(request)
        except commands.CommandError as exc:
            return self.bad_request(request, 'login', str(exc), 408 if isinstance(exc, SlowBody) else 400)
        password = body.get('password')
        if set(body) - {'password'} or not isinstance(password, str):
            return self.bad_request(request, 'login', 'login: expected {"password": "..."}')
        line = self.passwords.line()
        if line is None:
            return _refuse(503, self.passwords.problem)
        wait, ticket = self.limiter.attempt(addr)      # counted before the hash: no await in between
        if wait > 0:
            return self._rate_limited(addr, wait)
        if self._hash_slots is None:
            self._hash_slots = asyncio.Semaphore(HASH_SLOTS)
        loop = asyncio.get_running_loop()
        async with self._hash_slots:
            try:
                ok = await loop.run_in_executor(None, verify_password, password, line)
            except ValueError:          # the password file changed to something unusable meanwhile
                return _refuse(503, self.passwords.problem or 'password file unusable')
        if not ok:
            self.counters['login_failures'] += 1
            self.audit(addr, 'login', None, {'success': False, 'message': 'wrong password'}, 'warn')
            return _refuse(401, 'wrong password')
        self.limiter.success(addr, ticket)
        s = self.sessions.create(addr)
        self.counters['logins'] += 1
        self.audit(self.origin(request, s), 'login', None, {'success': True, 'message': 'logged in'})
        resp = _json({'ok': True, 'success': True, 'message': 'logged in', 'csrf': s.csrf})
        resp.set_cookie(COOKIE, s.token, httponly=True, samesite='Strict', path='/',
                        max_age=int(self.cfg['session_timeout']), secure=request.secure)
        return resp

    def _command_session(self, request: web.Request):
        """(session, None) when logged in with a valid CSRF token, else (None, refusal)."""
        s = self.session_of(request)
        if s is None:
            return None, _refuse(401, 'log in first: commands need the operator password')
        if not self.sessions.check_csrf(s, request.headers.get('X-CSRF-Token')):
            return None, _refuse(403, 'refused: missing or wrong CSRF token (reload the page)')
        return s, None

    async def logout(self, request: web.Request) -> web.Response:
        s, refused = self._command_session(request)
        if refused:
            return refused
        self.sessions.end(s.token)
        resp = _json({'ok': True, 'success': True, 'message': 'logged out'})
        resp.del_cookie(COOKIE, path='/')
        return resp

    # ------------------------------------------------------------------ commands
    async def command(self, request: web.Request) -> web.Response:
        name = request.match_info['name']
        s, refused = self._command_session(request)
        if refused:
            self.counters['commands_refused'] += 1
            self.audit(self.origin(request), name[:40], None,
                       {'success': False, 'message': 'not logged in / bad CSRF'}, 'warn')
            return refused
        origin = self.origin(request, s)
        try:
            body = await self._read_json(request)
            limits = self.backend.jog_limits()          # one per movement of the collector
            cmd = commands.validate(name, body, limits, axes=tuple(limits))
        except commands.CommandError as exc:
            self.counters['commands_refused'] += 1
            self.counters['bad_requests'] += 1
            self.audit(origin, name[:40], None, {'success': False, 'message': str(exc)}, 'warn')
            return _refuse(408 if isinstance(exc, SlowBody) else 400, str(exc))
        try:
            result = await self.backend.call(cmd)
        except Exception as exc:  # noqa: BLE001 - a failed call is an answer for the operator
            result = {'success': False, 'message': f'{cmd.service} failed: {exc}'}
        self.counters['commands'] += 1
        self.audit(origin, cmd.name, dict(cmd.request), result)
        return _json({'ok': True, 'command': cmd.name, 'service': cmd.service, 'summary': cmd.summary, **result})

    # ------------------------------------------------------------------ recorded days
    def _bag(self, request):
        root = self.backend.bag_dir()
        if not root:
            raise web.HTTPServiceUnavailable(text='bag directory unknown (recorder not answering)')
        bag = bags_mod.find_bag(root, request.match_info['name'])
        if bag is None:
            raise web.HTTPNotFound(text='no such bag')
        return bag

    async def bag_list(self, request: web.Request) -> web.Response:
        refused = self._view_refused(request)
        if refused:
            return refused
        root = self.backend.bag_dir()
        if not root:
            return _json({'bag_dir': None, 'bags': [], 'message': 'bag directory unknown: recorder not answering'})
        entries = await asyncio.get_running_loop().run_in_executor(None, bags_mod.list_bags, root)
        return _json({'bag_dir': str(root), 'bags': [e.to_json() for e in entries]})

    def _report_dir(self, bag: Path) -> Path:
        return user_path(self.cfg['report_dir']) / bag.name

    async def report(self, request: web.Request) -> web.Response:
        refused = self._view_refused(request)
        if refused:
            return refused
        bag = self._bag(request)
        out = self._report_dir(bag)
        async with self._report_lock:              # one report at a time (CPU on the Pi)
            if not bags_mod.report_is_fresh(bag, out):
                code, text = await self._make_report(bag, out)
                if code != 0:
                    return _refuse(422, f'the report failed (exit {code}): {text[-2000:]}')
        text = (out / 'report.txt').read_text(encoding='utf-8', errors='replace')
        plots = sorted(p.name for p in out.glob('*.png'))
        base = f'/api/bags/{bag.name}/report/'
        return _json({'bag': bag.name, 'text': text, 'plots': [base + p for p in plots]})

    async def _make_report(self, bag: Path, out: Path) -> tuple[int, str]:
        out.mkdir(parents=True, exist_ok=True)
        # the run's site config: the report's collector (its description) and site parameters
        config = getattr(self.backend, 'site_config', lambda: None)()
        proc = await asyncio.create_subprocess_exec(
            sys.executable, '-m', 'sslfr_bringup.cli', 'report', str(bag), '--out', str(out),
            *(['--config', str(config)] if config else []),
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
            env={**os.environ, 'MPLBACKEND': 'Agg'})
        try:
            data, _ = await asyncio.wait_for(proc.communicate(), REPORT_TIMEOUT)
        except asyncio.TimeoutError:
            proc.kill()
            await proc.wait()
            return -1, f'no report after {REPORT_TIMEOUT:.0f} s'
        text = data.decode('utf-8', errors='replace')
        if proc.returncode == 0 and not text.strip():
            return 1, 'the report printed nothing'
        if proc.returncode == 0:
            (out / 'report.txt').write_text(text, encoding='utf-8')
        return proc.returncode, text

    async def report_file(self, request: web.Request) -> web.StreamResponse:
        refused = self._view_refused(request)
        if refused:
            return refused
        bag = self._bag(request)
        name = request.match_info['file']
        out = self._report_dir(bag)
        files = {p.name for p in out.glob('*.png')} if out.is_dir() else set()
        if name not in files:
            raise web.HTTPNotFound(text='no such plot')
        return web.FileResponse(out / name)

    async def download(self, request: web.Request) -> web.StreamResponse:
        refused = self._view_refused(request)
        if refused:
            return refused
        bag = self._bag(request)
        resp = web.StreamResponse(headers={
            'Content-Type': 'application/zip',
            'Content-Disposition': f'attachment; filename="{bag.name}.zip"'})
        await resp.prepare(request)
        loop = asyncio.get_running_loop()
        gen = bags_mod.iter_zip(bag)
        try:
            while True:
                piece = await loop.run_in_executor(None, next, gen, None)
                if piece is None:
                    break
                await resp.write(piece)
        finally:
            gen.close()
        await resp.write_eof()
        return resp

    # ------------------------------------------------------------------ assembly
    def application(self) -> web.Application:
        app = web.Application(middlewares=[self.middleware], client_max_size=int(self.cfg['max_request_bytes']))
        app.add_routes([
            web.get('/', self.index), web.get('/static/{name}', self.static),
            web.get('/api/state', self.state), web.get('/api/history', self.history),
            web.get('/api/events', self.events), web.get('/api/session', self.session_info),
            web.post('/api/login', self.login), web.post('/api/logout', self.logout),
            web.post('/api/command/{name}', self.command),
            web.get('/api/bags', self.bag_list), web.get('/api/bags/{name}/report', self.report),
            web.get('/api/bags/{name}/report/{file}', self.report_file),
            web.get('/api/bags/{name}/download', self.download),
        ])

        async def start_pusher(app_):
            app_[PUSHER] = asyncio.create_task(self.pusher())

        async def stop_pusher(app_):
            app_[PUSHER].cancel()

        app.on_startup.append(start_pusher)
        app.on_cleanup.append(stop_pusher)
        return app


class Server:
    """The app served from its own thread and asyncio loop (the ROS executor keeps
    the main thread), behind the app's :class:`netguard.ConnectionGuard` (connection
    caps, header and idle time-outs). ``start()`` returns once listening (or raises
    OSError)."""

    def __init__(self, op: OperatorApp, host: str, port: int):
        self.op, self.host, self.port = op, host, int(port)
        self.loop = asyncio.new_event_loop()
        self._runner: web.AppRunner | None = None
        self._server: asyncio.base_events.Server | None = None
        self._thread = threading.Thread(target=self.loop.run_forever, name='web', daemon=True)
        self.url = ''

    def start(self) -> str:
        self._thread.start()
        fut = asyncio.run_coroutine_threadsafe(self._start(), self.loop)
        self.url = fut.result(30)
        return self.url

    async def _start(self) -> str:
        op = self.op
        self._runner = web.AppRunner(
            op.application(), access_log=None, shutdown_timeout=1.0,
            keepalive_timeout=float(op.cfg['idle_timeout']) + float(op.cfg['header_timeout']),  # backstop
            lingering_time=float(op.cfg['body_timeout']),
            logger=netguard.OneLineLogger('http', op.oneline))
        await self._runner.setup()
        self._server = await asyncio.get_running_loop().create_server(
            op.guard.wrap(self._runner.server), self.host, self.port, reuse_address=True, backlog=128)
        sock = self._server.sockets[0]
        host, port = sock.getsockname()[:2]
        shown = f'[{host}]' if ':' in host else host
        return f'http://{shown}:{port}/'

    async def _stop(self) -> None:
        if self._server is not None:
            self._server.close()
        if self._runner is not None:
            await self._runner.cleanup()
        self.op.guard.close_all()

    def stop(self) -> None:
        if self.loop.is_running():
            try:
                asyncio.run_coroutine_threadsafe(self._stop(), self.loop).result(5)
            except Exception:  # noqa: BLE001 - stopping anyway
                pass
            self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(5)
