"""The operator's console: a local web page (viser) showing the scene, each alternative's planned
motion and risk, the approval request with its buttons, and the behaviour tree, live.

Optional: ``pip install ".[console]"``. Start it with ``executive run SCENARIO --console`` or
``executive console RUN_OR_SCENARIO``; from Python, :class:`executive.console.console.Console`.
"""

#: The TCP port the console's page is served on unless told otherwise (on 127.0.0.1 only).
PORT = 8080
