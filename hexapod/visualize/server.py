"""The MeshCat server in a child process, listening on 127.0.0.1 only, and its probe.

``meshcat-server`` binds its web server to every interface; the server started here
patches tornado to bind to the loopback interface. Every wait has a timeout.
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from hexapod.exceptions import ViewerError

log = logging.getLogger(__name__)

#: Longest wait for any answer of the MeshCat server [s].
ZMQ_TIMEOUT = 5.0
#: Longest wait for a started MeshCat server to announce its addresses [s].
SERVER_START_TIMEOUT = 30.0

# The MeshCat server, with its web server bound to the loopback interface: meshcat's
# ZMQWebSocketBridge calls ``app.listen(port)``, which tornado binds to every interface.
_SERVER_CODE = """
import tornado.web
_listen = tornado.web.Application.listen
def _loopback_listen(self, port, address=None, **kwargs):
    return _listen(self, port, "127.0.0.1", **kwargs)
tornado.web.Application.listen = _loopback_listen
from meshcat.servers.zmqserver import main
main()
"""


def start_server(timeout: float) -> tuple[subprocess.Popen[bytes], str, str]:
    """Start a MeshCat server listening on 127.0.0.1 only.

    Returns:
        The child process, its ZeroMQ address and its web address.

    Raises:
        ViewerError: It did not announce its addresses within ``timeout`` [s].
    """
    env = dict(os.environ)
    import meshcat

    env["PYTHONPATH"] = os.pathsep.join(
        [str(Path(meshcat.__file__).parents[1]), env.get("PYTHONPATH", "")])
    proc = subprocess.Popen([sys.executable, "-u", "-c", _SERVER_CODE],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env,
                            start_new_session=True)
    atexit.register(stop_process, proc)
    lines: queue.Queue[str] = queue.Queue()

    def drain() -> None:  # keeps reading so that the server never blocks on a full pipe
        assert proc.stdout is not None
        for raw in proc.stdout:
            line = raw.decode("utf-8", "replace").strip()
            log.debug("meshcat-server: %s", line)
            lines.put(line)

    threading.Thread(target=drain, name="meshcat-server-output", daemon=True).start()
    urls: dict[str, str] = {}
    deadline = time.monotonic() + timeout
    while len(urls) < 2:
        remaining = deadline - time.monotonic()
        if remaining <= 0 or proc.poll() is not None:
            stop_process(proc)
            raise ViewerError("exited" if proc.poll() not in (None, -9, -15) else
                              "did not announce its addresses", timeout=timeout)
        with contextlib.suppress(queue.Empty):
            line = lines.get(timeout=min(remaining, 0.2))
            for key in ("zmq_url", "web_url"):
                if line.startswith(key + "="):
                    urls[key] = line.split("=", 1)[1]
    return proc, urls["zmq_url"], urls["web_url"]


def stop_process(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)


def probe(zmq_url: str, timeout: float) -> None:
    """Check that a MeshCat server answers at ``zmq_url`` within ``timeout`` [s]."""
    import zmq

    sock: Any = zmq.Context.instance().socket(zmq.REQ)
    sock.setsockopt(zmq.LINGER, 0)
    try:
        sock.connect(zmq_url)
        sock.send(b"url")
        if not sock.poll(int(timeout * 1000)):
            raise ViewerError("no answer", url=zmq_url, timeout=timeout)
        sock.recv()
    finally:
        sock.close()
