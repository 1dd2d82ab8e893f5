"""The listening addresses the editor knows by name, shared by the server and its access rules."""

from __future__ import annotations

LOOPBACK = "127.0.0.1"
WILDCARD_ADDRESSES = frozenset({"0.0.0.0", "::", "[::]", ""})
"""Addresses that listen on every interface."""
