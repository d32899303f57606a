"""Connecting the study to a Ray cluster: within a time limit, with an error that names the address.

Ray retries an unreachable cluster for minutes without a word, so :func:`connect_ray` first opens a TCP connection to
the address (refused or unroutable addresses fail at once or within the limit), then runs ``ray.init`` with the
same limit. Token authentication (Ray 2.52+) is configured through Ray's own environment variables; see the README's
cluster section and :data:`AUTH_HINT`.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from typing import Any

DEFAULT_CONNECT_TIMEOUT = 30.0  # seconds

AUTH_HINT = (
    "If the cluster uses token authentication (Ray 2.52 and later; `ray start --head` turns it on when a "
    "token exists, e.g. ~/.ray/auth_token), set RAY_AUTH_MODE=token and the cluster's token "
    "(RAY_AUTH_TOKEN, or RAY_AUTH_TOKEN_PATH, or the default file ~/.ray/auth_token) before running genrl; "
    "a cluster started with RAY_AUTH_MODE=disabled needs RAY_AUTH_MODE=disabled here too."
)


class RayConnectionError(ConnectionError, ValueError):
    """No connection to the Ray cluster at the given address (a ``ValueError`` too: the address is unusable)."""


def split_address(address: str) -> tuple[str, int]:
    """``(host, port)`` of ``HOST:PORT``, ``[IPV6]:PORT`` or ``ray://HOST:PORT``.

    :param address: a Ray cluster address
    """
    rest = address.split("://", 1)[1] if "://" in address else address
    host, _, port = rest.rpartition(":")
    host = host.strip("[]")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise RayConnectionError(f"Ray address {address!r} is not of the form HOST:PORT (e.g. 10.0.0.1:6379)")
    return host, int(port)


def connect_ray(address: str | None, timeout: float = DEFAULT_CONNECT_TIMEOUT, **init_kwargs: Any) -> None:
    """``ray.init`` of the cluster at ``address`` within ``timeout`` seconds, or a :class:`RayConnectionError`.

    Does nothing when Ray is already initialised. Without an address (and no ``RAY_ADDRESS``), Ray starts a local
    instance, which is not bounded by ``timeout``.

    :param address: ``HOST:PORT`` of the head's GCS (``ray start --head --port``), ``ray://HOST:PORT``, ``auto``,
        or None
    :param timeout: seconds allowed for reaching the address and for ``ray.init``
    :param init_kwargs: more arguments of ``ray.init``
    """
    import ray

    if ray.is_initialized():
        return
    if not timeout > 0:
        raise ValueError(f"timeout must be a positive number of seconds, got {timeout!r}")
    target = address or os.environ.get("RAY_ADDRESS")
    if target in (None, "", "auto", "local"):
        ray.init(address=address, **init_kwargs)
        return
    began = time.monotonic()
    host, port = split_address(target)
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as error:
        raise RayConnectionError(
            f"cannot reach the Ray cluster at {target} within {timeout:g} s: {error}. Is the head "
            "running (`ray start --head --port=PORT`) and is the address right?"
        ) from None
    outcome: dict[str, BaseException] = {}

    def init() -> None:
        try:
            ray.init(address=address, **init_kwargs)
        except BaseException as error:  # handed to the caller's thread
            outcome["error"] = error

    thread = threading.Thread(target=init, name="ray-connect", daemon=True)
    thread.start()
    thread.join(max(timeout - (time.monotonic() - began), 1.0))
    if thread.is_alive():
        raise RayConnectionError(
            f"no connection to the Ray cluster at {target} within {timeout:g} s (the address "
            f"accepts connections, but Ray did not answer). {AUTH_HINT}"
        )
    if "error" in outcome:
        error = outcome["error"]
        raise RayConnectionError(f"cannot connect to the Ray cluster at {target}: {error}. {AUTH_HINT}") from error
