"""The byte link to a GCS controller: a TCP socket or a serial port (pyserial).

Both read GCS answers the same way: bytes accumulate until an LF that does not follow
a space (:func:`hexapod.backends.gcs_protocol.answer_end`). A closed connection raises
:class:`~hexapod.link_errors.GcsDisconnectedError`, a missing answer
:class:`~hexapod.link_errors.GcsTimeoutError`.
"""

from __future__ import annotations

import contextlib
import socket
import time
from abc import ABC, abstractmethod

import serial  # pyserial

from hexapod.backends import gcs_protocol as gp
from hexapod.backends.base import write_failed
from hexapod.link_errors import GcsDisconnectedError, GcsLinkError, GcsTimeoutError

__all__ = ["SerialTransport", "TcpTransport", "Transport", "open_transport"]


class Transport(ABC):
    """A byte link that reads whole GCS answers.

    Args:
        url: The address (for messages).
        timeout: The default wait for an answer [s] (for messages).
    """

    def __init__(self, url: str, timeout: float) -> None:
        self.url = url
        self.timeout = timeout
        self._buf = bytearray()

    @abstractmethod
    def write(self, data: bytes, command: str) -> None:
        """Send bytes.

        Raises:
            GcsDisconnectedError: The link is gone.
        """

    @abstractmethod
    def _recv(self, timeout: float) -> bytes:
        """Bytes that arrive within ``timeout`` [s] (b"" if none).

        Raises:
            GcsDisconnectedError: The link is gone.
        """

    @abstractmethod
    def close(self) -> None:
        """Close the link (idempotent, never raises)."""

    def read_answer(self, command: str, deadline: float) -> bytes:
        """The next complete answer (``perf_counter`` ``deadline`` [s]).

        Raises:
            GcsTimeoutError: No complete answer before the deadline.
            GcsDisconnectedError: The link closed.
        """
        while True:
            end = gp.answer_end(self._buf)
            if end >= 0:
                out = bytes(self._buf[:end])
                del self._buf[:end]
                return out
            left = deadline - time.perf_counter()
            if left <= 0:
                got = bytes(self._buf)
                self._buf.clear()
                raise GcsTimeoutError(self.url, command, self.timeout, got)
            self._buf += self._recv(left)

    def discard_input(self) -> None:
        """Forget what was received and not read (before a halt)."""
        self._buf.clear()
        with contextlib.suppress(GcsLinkError):
            while self._recv(0.0):
                pass


class TcpTransport(Transport):
    """A TCP connection (``tcp://HOST:PORT``; a C-887 listens on port 50000)."""

    def __init__(self, host: str, port: int, timeout: float) -> None:
        super().__init__(f"tcp://{host}:{port}", timeout)
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as exc:
            raise GcsLinkError(self.url, f"cannot connect: {exc}") from exc
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def write(self, data: bytes, command: str) -> None:
        try:
            self._sock.sendall(data)
        except OSError as exc:
            raise GcsDisconnectedError(self.url, f"send failed: {exc}", command) from exc

    def _recv(self, timeout: float) -> bytes:
        try:
            if timeout <= 0:
                self._sock.setblocking(False)
            else:
                self._sock.settimeout(timeout)
            data = self._sock.recv(65536)
        except (TimeoutError, BlockingIOError):
            return b""
        except OSError as exc:
            raise GcsDisconnectedError(self.url, f"receive failed: {exc}") from exc
        if not data:
            raise GcsDisconnectedError(self.url, "the controller closed the connection")
        return data

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self._sock.close()


class SerialTransport(Transport):
    """A serial port through ``serial.serial_for_url`` (RS-232, a pty, ``socket://``)."""

    def __init__(self, url: str, timeout: float, baudrate: int = 115200) -> None:
        super().__init__(f"serial:{url}", timeout)
        try:
            self._port = serial.serial_for_url(url, baudrate=baudrate, timeout=timeout,
                                               write_timeout=timeout)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise GcsLinkError(self.url, f"cannot open the port: {exc}") from exc

    def write(self, data: bytes, command: str) -> None:
        try:
            self._port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise GcsDisconnectedError(self.url, write_failed(exc), command) from exc

    def _recv(self, timeout: float) -> bytes:
        try:
            self._port.timeout = max(timeout, 0.0)
            data: bytes = self._port.read(max(1, self._port.in_waiting))
        except (serial.SerialException, OSError) as exc:
            text = str(exc)  # pyserial's socket:// already says "read failed: ..."
            problem = text if text.startswith("read failed") else f"read failed: {text}"
            raise GcsDisconnectedError(self.url, problem) from exc
        return data

    def close(self) -> None:
        with contextlib.suppress(serial.SerialException, OSError):
            self._port.close()


def open_transport(url: str, timeout: float, baudrate: int = 115200) -> Transport:
    """The link of ``tcp://HOST:PORT`` or ``serial:URL``.

    Raises:
        GcsLinkError: Another scheme, or the link cannot be opened.
    """
    if url.startswith("tcp://"):
        host, sep, port = url.removeprefix("tcp://").rpartition(":")
        if not sep or not port.isdigit():
            raise GcsLinkError(url, "expected tcp://HOST:PORT")
        return TcpTransport(host.strip("[]"), int(port), timeout)
    if url.startswith("serial:") and len(url) > len("serial:"):
        return SerialTransport(url.removeprefix("serial:"), timeout, baudrate)
    raise GcsLinkError(url, "expected tcp://HOST:PORT or serial:URL (a pyserial URL)")
