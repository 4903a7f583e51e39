"""A registry app served by uvicorn in a background thread on the loopback interface (tests, benchmarks).

``with serve_in_thread(app) as base_url: ...`` binds 127.0.0.1 on a port the OS picks (no race for a
"free" port), waits until uvicorn accepts connections, and on exit asks it to stop and joins the
thread, all within bounded times.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

LOOPBACK = "127.0.0.1"


@contextmanager
def serve_in_thread(app, host: str = LOOPBACK, start_timeout_s: float = 20.0, stop_timeout_s: float = 20.0) -> Iterator[str]:
    """Serve ``app`` on ``host`` (loopback only) at an OS-chosen port; yields ``http://host:port``."""
    import uvicorn

    if host not in (LOOPBACK, "localhost", "::1"):
        raise ValueError(f"serve_in_thread only binds loopback addresses, not {host!r}")
    config = uvicorn.Config(app, host=host, port=0, log_level="warning", access_log=False, lifespan="on")
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, name="registry-uvicorn", daemon=True)
    thread.start()
    deadline = time.monotonic() + start_timeout_s
    while not server.started:
        if not thread.is_alive():
            raise RuntimeError("uvicorn stopped while starting (see its log above)")
        if time.monotonic() > deadline:
            server.should_exit = True
            thread.join(stop_timeout_s)
            raise RuntimeError(f"uvicorn did not start within {start_timeout_s:g} s")
        time.sleep(0.02)
    port = server.servers[0].sockets[0].getsockname()[1]
    try:
        yield f"http://{host}:{port}"
    finally:
        server.should_exit = True
        thread.join(stop_timeout_s)
        if thread.is_alive():  # connections that would not close: stop waiting for them
            server.force_exit = True
            thread.join(stop_timeout_s)
