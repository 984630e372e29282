"""The graphic display: the map, and a session as it compiles, on a local web page.

The APY injected a graphic display into the optics, superposing the
compiled data on the map and the stereo model at a scale factor of 0.25 to
25 (1x lies on the map). apygis draws it on a web page served to this
machine's browser:

* :mod:`~apygis.view.scene` -- what is drawn, as JSON-ready data (records,
  pens of the plot, symbol bitmaps);
* :mod:`~apygis.view.hub` -- the state the pages show and one bounded queue
  per page (a page that falls behind is sent the whole state: nothing lost,
  nobody waits);
* :mod:`~apygis.view.server` -- the web server (aiohttp on a thread of its
  own; every address under a secret token; view only);
* :mod:`~apygis.view.feed` -- a map's hub; a session's replica (its journal
  replayed) and the changes it makes; the session's mark and status line;
  an orientation's control points as overlays;
* :mod:`~apygis.view.process` -- a session's server in a process of its own,
  which follows the session's journal (serving pages takes nothing from the
  compilation);
* ``static/`` -- the page: plain JavaScript drawing on a canvas, nothing
  loaded from elsewhere.

Layering: this package imports :mod:`apygis.model`, :mod:`apygis.compile`
(the effects it shows), the pens of :mod:`apygis.plot.plotdef`, the
session's journal and engine set-up (:mod:`apygis.session`, to replay a
session) and the floor; the session does not import it, the command line
wires the two.
"""

from apygis.view.feed import (
    ChangeFeed,
    SessionFeed,
    SessionReplica,
    control_overlays,
    deliver,
    map_hub,
    session_hub,
)
from apygis.view.hub import Viewer, ViewHub
from apygis.view.process import ViewProcess
from apygis.view.server import ViewServer, is_loopback

__all__ = [
    "ChangeFeed",
    "SessionFeed",
    "SessionReplica",
    "ViewHub",
    "ViewProcess",
    "ViewServer",
    "Viewer",
    "control_overlays",
    "deliver",
    "is_loopback",
    "map_hub",
    "session_hub",
]
