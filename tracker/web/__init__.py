"""The live view for commissioning: a page served by the tracker itself (``tracker run --web``).

``LiveView`` (view.py) is a sink that only keeps a reference to the newest frame and result;
``WebServer`` (server.py) serves the page, the annotated image and the state from its own
threads. Nothing here ever makes the loop wait.
"""

from tracker.web.server import WebServer
from tracker.web.view import LiveView

__all__ = ["LiveView", "WebServer"]
