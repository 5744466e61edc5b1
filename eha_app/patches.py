"""Where the server changes a library's behaviour beyond its public API, in one place.

Each change names the library versions it was written against and has a test
that it takes effect (``tests/serve/test_hardening.py``): a library upgrade that
moves the internals fails that test instead of silently dropping the change.

Component resources (Panel 1.9, ``panel.io.server.ComponentResourceHandler``)
    Panel serves ``/components/<module>/<class>/<attribute>/<path>`` for
    custom components' CSS and JavaScript, and resolves the URL by importing
    ``<module>``: any module on the server's path, named by anyone who can
    reach the server (an ``<img>`` on any page a student opens will do).
    ``/components/eha_app.cli.__main__/x/_css/a`` once made the server re-read
    its own command line and exit; ``/components/this/...`` printed into the
    log. :func:`refuse_foreign_components` makes the route answer 404 unless
    the module is already loaded, belongs to Panel or to this app, and the
    name is a Parameterized class (every Panel component is one); the
    component's own checks (listed attribute, listed file) still apply.
"""

from __future__ import annotations

import sys

__all__ = ["COMPONENT_PACKAGES", "WRITTEN_FOR", "component_allowed", "refuse_foreign_components"]

#: The library versions these changes were written against (checked by the tests).
WRITTEN_FOR = {"panel": "1.9", "bokeh": "3.9"}

#: Top-level packages whose components' resources the server may serve.
COMPONENT_PACKAGES = ("panel", "eha_app")


def component_allowed(path: str) -> bool:
    """May ``/components/<path>`` be resolved? Only for a Parameterized class of a module of
    :data:`COMPONENT_PACKAGES` that is already loaded: a request never imports anything.

    >>> component_allowed("panel.template.vanilla/VanillaTemplate/_css/vanilla.css")
    True
    >>> component_allowed("eha_app.cli.__main__/x/_css/a"), component_allowed("this/x/_css/a")
    (False, False)
    """
    import param

    module_name, _, rest = path.partition("/")
    cls_name = rest.partition("/")[0]
    if module_name.split(".")[0] not in COMPONENT_PACKAGES:
        return False
    module = sys.modules.get(module_name)
    component = getattr(module, cls_name, None) if module is not None and cls_name else None
    return isinstance(component, type) and issubclass(component, param.Parameterized)


def refuse_foreign_components() -> None:
    """Answer 404 to every ``/components/`` request :func:`component_allowed` refuses.

    Call before the server builds its routes (``panel serve`` does so when it
    starts): Panel looks ``ComponentResourceHandler`` up in its module then.
    Calling it again does nothing.
    """
    import panel.io.server as panel_server
    from tornado.web import HTTPError

    base = panel_server.ComponentResourceHandler
    if getattr(base, "eha_guarded", False):
        return

    class GuardedComponentResourceHandler(base):
        eha_guarded = True

        def parse_url_path(self, path: str) -> str:
            if not component_allowed(path):
                raise HTTPError(404, "Not found")
            try:
                return super().parse_url_path(path)
            except HTTPError:
                raise
            except Exception:  # noqa: BLE001 - a resource attribute Panel cannot list (None, ...): not found
                raise HTTPError(404, "Not found") from None

        def write_error(self, status_code, **kwargs):
            # a short answer: no traceback, no echo of the path asked for
            self.finish(f"{status_code}: not found" if status_code == 404 else str(status_code))

    panel_server.ComponentResourceHandler = GuardedComponentResourceHandler
