"""Host parsing and who may use the editor by listen address."""

from __future__ import annotations

import pytest

from wise.editor.access import access_for, split_host
from wise.editor.app import COOKIE


@pytest.mark.parametrize(
    "header, expected",
    [
        ("localhost", ("localhost", None)),
        ("LocalHost:8000", ("localhost", 8000)),
        ("localhost.:80", ("localhost", 80)),
        ("127.0.0.1:65535", ("127.0.0.1", 65535)),
        ("[::1]:8000", ("[::1]", 8000)),
        ("[0:0:0:0:0:0:0:1]", ("[::1]", None)),
        ("::1", None),
        ("[::1", None),
        ("[::1]x", None),
        ("localhost:0", None),
        ("localhost:99999", None),
        ("localhost:80a", None),
        ("user@localhost", None),
        ("", None),
    ],
)
def test_host_headers_are_parsed_strictly(header: str, expected: tuple | None) -> None:
    assert split_host(header) == expected


def test_access_by_listen_address() -> None:
    assert access_for("127.0.0.1", 8000, None).hosts == {"localhost", "127.0.0.1", "[::1]"}
    assert access_for("::1", 8000, None).hosts == {"localhost", "127.0.0.1", "[::1]"}
    specific = access_for("192.168.1.20", 8000, "t")
    assert specific.allows("192.168.1.20") and not specific.allows("192.168.1.21") and specific.token == "t"
    wildcard = access_for("0.0.0.0", 8000, "t")
    assert wildcard.allows("10.1.2.3") and wildcard.allows("[fe80::1]") and not wildcard.allows("attacker.example")
    assert wildcard.cookie(COOKIE) == f"{COOKIE}_8000"
