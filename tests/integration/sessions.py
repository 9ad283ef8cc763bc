"""Loopback Zenoh sessions for the integration tests: a router that listens and a client that
dials it, with the project's own session settings (`eifp_wire.session_settings`)."""

from __future__ import annotations

import zenoh

from eifp_wire import session_settings


def open_session(mode: str, endpoint: str) -> zenoh.Session:
    """A router listening on `endpoint` (mode "router"), else a client dialling it."""
    conf = zenoh.Config()
    if mode == "router":
        settings = session_settings(mode="router", listen=[endpoint])
    else:
        settings = session_settings(mode="client", connect=[endpoint], connect_timeout_ms=5000)
    for key, value in settings.items():
        conf.insert_json5(key, value)
    return zenoh.open(conf)
