"""Click-to-annotate in the browser: the page and local server behind ``rce annotate VIDEO``.

:mod:`.snap` moves a click onto the centre line of the stem under it; :mod:`.server` serves the page
(``static/``: HTML, JS, CSS shipped as package data) and writes ``annotations.json`` and ``graph.json``;
:mod:`.review` is the session behind ``rce review VIDEO TRACKS.csv`` (scrub, correct, re-track), on the same server.
"""

from .server import AnnotationServer, AnnotationSession, make_server
from .snap import RidgeSnapper, SnapResult

__all__ = ["AnnotationServer", "AnnotationSession", "RidgeSnapper", "SnapResult", "make_server"]
