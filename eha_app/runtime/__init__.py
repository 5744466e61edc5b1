"""How the app is served and computes, whatever it shows.

- :mod:`~eha_app.runtime.serving`: ``panel serve``'s command line, several processes, nginx;
- :mod:`~eha_app.runtime.jobs`: the fair queue of computations shared by the sessions of a process;
- :mod:`~eha_app.runtime.tasks`: a session's runs on that queue, and the one locked path by which
  everything reaches a page;
- :mod:`~eha_app.runtime.limits`: what one request may cost;
- :mod:`~eha_app.runtime.connection`: the page's link to the server (lost, back, the address);
- :mod:`~eha_app.runtime.patches`: every change to a library's internals, and the strict mode;
- :mod:`~eha_app.runtime.redaction`: secrets out of the log;
- :mod:`~eha_app.runtime.handins`: an exercise's hand-ins in SQLite.

Nothing here imports the layers above (rendering, sessions, sections).
"""
