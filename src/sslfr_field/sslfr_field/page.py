"""The field page: every collector of a field at a glance, commands to one or all.

The HTTP side of the ``field_page`` node. It is the collector's operator page's own
code (sslfr_web.app.OperatorApp: password file, sessions, CSRF token, login rate
limit, same-origin check, security headers, audit file) with field routes:

- ``GET /`` the page, ``GET /api/field`` the live state (:mod:`sslfr_field.live`),
  ``GET /api/session``, ``POST /api/login``, ``POST /api/logout`` as on the collector;
- ``POST /api/command/{stow|mode}`` with ``{"collector": ID or "all", "mode": ...}``:
  the collector's own ``<namespace>/planner/set_mode`` service, one call per collector
  (``all``: every collector of the field, in parallel); each call audited with the
  collector's id. Commands need the operator login and the CSRF token.
"""
from __future__ import annotations

import asyncio
from pathlib import Path

from aiohttp import web
from sslfr_web import commands
from sslfr_web.app import OperatorApp, _json, _refuse
from sslfr_common.params import ParamSpec, ParamTable

from .live import DEFAULT_LOST_AFTER

STATIC = Path(__file__).resolve().parent / 'static'
#: the collector page's parameters the field page does not take (its own ``port`` and
#: ``audit_file``; the day plots, jogs and recorded days are the collector page's); every
#: other one (login, sessions, connection and request limits) it shares, same meaning and ranges
NOT_SHARED = ('port', 'audit_file', 'plot_period', 'max_jog', 'bag_dir', 'report_dir')
#: field commands: each is a collector page command through the collector's planner/set_mode
FIELD_COMMANDS = ('stow', 'mode')


def field_page_params() -> ParamTable:
    """The ``field_page`` node's parameters: the collectors and the shared page limits."""
    from sslfr_web.params import WEB_PARAMS
    shared = [s for s in WEB_PARAMS if s.name not in NOT_SHARED]
    return ParamTable((
        ParamSpec('collectors', [''], 'namespaces of the field\'s collectors, e.g. [/c1, /c2]', read_only=True),
        ParamSpec('collector_ids', [''], 'the collectors\' ids, in the order of collectors', read_only=True),
        ParamSpec('collector_pages', [''], 'each collector\'s operator page URL ([] or one per collector)',
                  read_only=True),
        ParamSpec('collector_configs', [''],
                  "each collector's site config (path), for its absorbed energy of the day "
                  "([] or one per collector; '' for a collector without one: no absorbed energy)", read_only=True),
        ParamSpec('port', 8090, 'TCP port of the field page (0: any free port, logged at start-up)', '-',
                  0, 65535, read_only=True),
        ParamSpec('lost_after', DEFAULT_LOST_AFTER, 'a collector silent this long is shown lost [s, steady]',
                  's', 0.5, 600.0, read_only=True),
        ParamSpec('audit_file', '~/.local/state/sslfr/field_commands.jsonl',
                  "every field command (and refusal) as a JSON line with its origin ('' = the log only)",
                  read_only=True),
        *shared), _check_lists, integers_for_floats=True)


def _check_lists(v: dict) -> list[str]:
    nsp = [n for n in v['collectors'] if n]
    ids = [i for i in v['collector_ids'] if i]
    pages = [p for p in v['collector_pages'] if p]
    errors = []
    if not nsp:
        errors.append('collectors is empty: the field page needs the collectors\' namespaces')
    if len(ids) != len(nsp):
        errors.append(f'collector_ids has {len(ids)} ids for {len(nsp)} collectors')
    if len(set(ids)) != len(ids) or len(set(nsp)) != len(nsp):
        errors.append('collectors and collector_ids must be unique')
    if pages and len(pages) != len(nsp):
        errors.append(f'collector_pages has {len(pages)} URLs for {len(nsp)} collectors')
    configs = list(v['collector_configs'])
    if configs != [''] and len(configs) != len(nsp):
        errors.append(f'collector_configs has {len(configs)} entries for {len(nsp)} collectors')
    return errors


class FieldApp(OperatorApp):
    """The field page: the operator page's login, limits and audit; field routes."""

    def __init__(self, cfg: dict, backend, collectors: dict[str, str]):
        super().__init__(cfg, backend)
        self.collectors = dict(collectors)           # id -> namespace

    async def index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / 'field.html', headers={'Cache-Control': 'no-cache'})

    async def static(self, request: web.Request) -> web.StreamResponse:
        name = request.match_info['name']
        if name not in {p.name for p in STATIC.iterdir() if p.is_file()}:
            raise web.HTTPNotFound()
        return web.FileResponse(STATIC / name, headers={'Cache-Control': 'no-cache'})

    async def field(self, request: web.Request) -> web.Response:
        return self._view_refused(request) or _json(self.backend.snapshot())

    async def command(self, request: web.Request) -> web.Response:
        name = request.match_info['name']
        s, refused = self._command_session(request)
        if refused:
            self.counters['commands_refused'] += 1
            self.audit(self.origin(request), name, None, {'success': False, 'message': 'not logged in / bad CSRF'},
                       'warn')
            return refused
        origin = self.origin(request, s)
        try:
            body = dict(await self._read_json(request))
            target = body.pop('collector', None)
            if name not in FIELD_COMMANDS:
                raise commands.CommandError(f'{name}: not a field command (field commands: {", ".join(FIELD_COMMANDS)})')
            if target != 'all' and target not in self.collectors:
                raise commands.CommandError(f'collector: expected "all" or one of {", ".join(self.collectors)}, '
                                            f'got {target!r}')
            cmd = commands.validate(name, body)
        except commands.CommandError as exc:
            self.counters['commands_refused'] += 1
            self.audit(origin, name, None, {'success': False, 'message': str(exc)}, 'warn')
            return _refuse(400, str(exc))
        ids = list(self.collectors) if target == 'all' else [target]

        async def one(cid):
            try:
                return await self.backend.call(cid, cmd)
            except Exception as exc:  # noqa: BLE001 - a failed call is an answer for the operator
                return {'success': False, 'message': f'{cmd.service} failed: {exc}'}
        results = dict(zip(ids, await asyncio.gather(*(one(c) for c in ids))))
        for cid, result in results.items():
            self.counters['commands'] += 1
            self.audit(origin, f'{cid}: {cmd.name}', dict(cmd.request), result)
        ok = all(r.get('success') for r in results.values())
        return _json({'ok': True, 'success': ok, 'command': cmd.name, 'summary': cmd.summary,
                      'message': '; '.join(f'{c}: {"done" if r.get("success") else "refused"}'
                                           f'{": " + r["message"] if r.get("message") else ""}'
                                           for c, r in results.items()),
                      'results': results})

    def application(self) -> web.Application:
        app = web.Application(middlewares=[self.middleware], client_max_size=int(self.cfg['max_request_bytes']))
        app.add_routes([
            web.get('/', self.index), web.get('/static/{name}', self.static),
            web.get('/api/field', self.field), web.get('/api/session', self.session_info),
            web.post('/api/login', self.login), web.post('/api/logout', self.logout),
            web.post('/api/command/{name}', self.command),
        ])
        return app
