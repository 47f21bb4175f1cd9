"""The view's public port: a byte relay to the Foxglove SDK's server that also lets in clients of the open
protocol's older name.

The SDK's server accepts the WebSocket subprotocol `foxglove.sdk.v1` only and answers HTTP 400 to a client
that offers nothing but `foxglove.websocket.v1` (Lichtblick, every `@foxglove/ws-protocol` 0.8 client), though
both carry the same messages. The relay reads each connection's HTTP upgrade request, asks the server for
`foxglove.sdk.v1` where the client offered only the older name, gives the client back the name it offered,
then copies bytes both ways untouched (a WebSocket frame does not name its subprotocol, and the handshake's
accept key depends on the client's key alone).
"""

from __future__ import annotations

import contextlib
import re
import socket
import threading

SDK = 'foxglove.sdk.v1'
OPEN = 'foxglove.websocket.v1'
HEAD_MAX = 64 * 1024  # bytes of HTTP head a client may send before the relay gives up on it
HEAD_TIMEOUT = 10.0  # seconds for a client's (or the server's) HTTP head
BUFFER = 256 * 1024
_PROTOCOL = re.compile(rb'(?im)^sec-websocket-protocol:[ \t]*([^\r\n]*)\r\n')


def _read_head(connection: socket.socket) -> tuple[bytes, bytes] | None:
    """(HTTP head with its blank line, bytes read past it), or None when the peer gave none in time."""
    data = b''
    connection.settimeout(HEAD_TIMEOUT)
    while b'\r\n\r\n' not in data:
        if len(data) > HEAD_MAX:
            return None
        chunk = connection.recv(4096)
        if not chunk:
            return None
        data += chunk
    connection.settimeout(None)
    end = data.index(b'\r\n\r\n') + 4
    return data[:end], data[end:]


def offered(head: bytes) -> list[str]:
    """The subprotocols an upgrade request offers, in order."""
    return [p.strip() for m in _PROTOCOL.finditer(head) for p in m.group(1).decode('latin-1').split(',') if p.strip()]


def for_server(head: bytes) -> tuple[bytes, bool]:
    """The request as the SDK's server accepts it, and whether the answer's subprotocol must be renamed back."""
    names = offered(head)
    if SDK in names or OPEN not in names:
        return head, False
    return _PROTOCOL.sub(lambda m: m.group(0).replace(m.group(1), SDK.encode()), head, count=1), True


def for_client(head: bytes) -> bytes:
    """The server's answer with the subprotocol the client offered."""
    return _PROTOCOL.sub(lambda m: m.group(0).replace(m.group(1), OPEN.encode()), head, count=1)


class Relay:
    """Listens on (host, port) and relays every connection to the server at 127.0.0.1:`inner`."""

    def __init__(self, host: str, port: int, inner: int) -> None:
        self.inner = inner
        self.listener = socket.create_server((host, port), reuse_port=False)
        self.port = self.listener.getsockname()[1]
        self._connections: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._closed = False
        self._thread = threading.Thread(target=self._accept, name='foxglove-relay', daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self.listener.accept()
            except OSError:
                return  # closed
            threading.Thread(target=self._serve, args=(client,), name='foxglove-relay-conn', daemon=True).start()

    def _track(self, *connections: socket.socket) -> bool:
        with self._lock:
            if self._closed:
                return False
            self._connections.update(connections)
            return True

    def _serve(self, client: socket.socket) -> None:
        server: socket.socket | None = None
        try:
            if not self._track(client):
                return
            read = _read_head(client)
            if read is None:
                return
            head, rest = read
            request, rename = for_server(head)
            server = socket.create_connection(('127.0.0.1', self.inner), timeout=HEAD_TIMEOUT)
            if not self._track(server):
                return
            server.sendall(request + rest)
            answer = _read_head(server)
            if answer is None:
                return
            response, early = answer
            client.sendall((for_client(response) if rename else response) + early)
            pump = threading.Thread(target=_copy, args=(server, client), name='foxglove-relay-down', daemon=True)
            pump.start()
            _copy(client, server)
            pump.join()
        except OSError:
            pass
        finally:
            for connection in (client, server):
                if connection is not None:
                    with self._lock:
                        self._connections.discard(connection)
                    with contextlib.suppress(OSError):
                        connection.close()

    def close(self) -> None:
        """Stop listening and cut every relayed connection."""
        with self._lock:
            self._closed = True
            connections = list(self._connections)
        with contextlib.suppress(OSError):
            self.listener.close()
        for connection in connections:
            with contextlib.suppress(OSError):
                connection.shutdown(socket.SHUT_RDWR)
        self._thread.join(timeout=5)


def _copy(source: socket.socket, target: socket.socket) -> None:
    """Bytes from one side to the other until either ends; then both directions end."""
    buffer = bytearray(BUFFER)
    view = memoryview(buffer)
    try:
        while True:
            count = source.recv_into(buffer)
            if not count:
                break
            target.sendall(view[:count])
    except OSError:
        pass
    finally:
        for side in (source, target):
            with contextlib.suppress(OSError):
                side.shutdown(socket.SHUT_RDWR)
