"""The console's web server: viser, on 127.0.0.1 only, with no public share link.

viser (``pip install ".[console]"``) serves a prebuilt three.js client and keeps every
connected page in sync with the scene and panel the server builds. :func:`start_server`
binds it to the loopback interface only (nobody else on the network can open the page),
hides the page's share button and refuses the share request the client could still send
(which would open a tunnel through viser's public relay), and keeps viser's banner off the
terminal. :func:`require_viser` turns a missing extra into a :class:`ConsoleError` naming
what to install.
"""

from __future__ import annotations

import contextlib
import io
from types import ModuleType
from typing import TYPE_CHECKING

from executive.console import PORT
from executive.errors import ExecutiveError

if TYPE_CHECKING:
    import viser

__all__ = ["HOST", "INSTALL_HINT", "ConsoleError", "require_viser", "start_server", "stop_server"]

HOST = "127.0.0.1"
INSTALL_HINT = 'pip install ".[console]"'


class ConsoleError(ExecutiveError):
    """The console cannot start: its optional dependency is missing, or its input is unusable."""


def require_viser() -> ModuleType:
    """The ``viser`` module, or a :class:`ConsoleError` saying how to install it."""
    try:
        import viser
    except ImportError as exc:
        raise ConsoleError(
            f"the console needs the optional extra 'console' (viser), which is not installed "
            f"({exc}); install it with: {INSTALL_HINT}"
        ) from None
    return viser


def start_server(port: int = PORT, *, title: str = "executive") -> viser.ViserServer:
    """A viser server on ``127.0.0.1:port`` (0: any free port; a busy port: viser takes the next free).

    Args:
        port: TCP port to try first.
        title: the label at the top of the page's panel.

    Returns:
        The running server; :func:`stop_server` stops it. ``server.get_port()`` is the port bound.

    Raises:
        ConsoleError: viser is not installed.
    """
    module = require_viser()

    class LocalServer(module.ViserServer):  # type: ignore[name-defined]
        """A viser server that never asks viser's relay for a public share link."""

        def request_share_url(self, verbose: bool = True) -> str | None:
            return None

    with contextlib.redirect_stdout(io.StringIO()):  # viser prints a banner with the address
        server = LocalServer(host=HOST, port=port, label=title, verbose=False)
    server.gui.configure_theme(show_share_button=False, control_width="large", show_logo=False)
    return server


def stop_server(server: viser.ViserServer) -> None:
    """Stop ``server`` (and its threads) without viser's goodbye line on the terminal."""
    with contextlib.redirect_stdout(io.StringIO()):
        server.stop()
