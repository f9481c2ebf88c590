"""Network addresses as the bridge prints and reads them: an IPv6 host goes in brackets before
``:PORT`` (``[::1]:5760``, ``socket://[::1]:5760``), as pyserial, ``--http`` and browsers read
it; ``::1:5760`` would not parse back."""

from __future__ import annotations

__all__ = ["host_text", "socket_url"]


def host_text(host: str) -> str:
    """``host`` as it goes before ``:PORT``: an IPv6 address in brackets."""
    return f"[{host}]" if ":" in host else host


def socket_url(host: str, port: int) -> str:
    """``socket://HOST:PORT``, an IPv6 host in brackets (as ``parse_socket_url`` and pyserial
    read it back)."""
    return f"socket://{host_text(host)}:{port}"
