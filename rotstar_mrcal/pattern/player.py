"""player.html: the display loop, full screen, one PNG pixel per device pixel

SYNOPSIS

    >>> import json, os, tempfile
    >>> from rotstar_mrcal.cli.pattern import main as rotstar_pattern
    >>> from rotstar_mrcal.pattern.player import write_player
    >>> out = tempfile.mkdtemp()
    >>> rotstar_pattern(["--out", out, "--screen", "800x600", "--pitch", "100", "--band", "24"])
    0
    >>> fn = write_player(out, hold=20)          # rotstar-pattern already wrote one
    >>> os.path.basename(fn), os.path.getsize(fn) > 10000
    ('player.html', True)

One self-contained page: the frame PNGs are embedded (base64) together with
the loop (display/loop.py) and the screen size of pattern.json, so the file
can be copied or served alone. The page

- decodes every PNG once into an ImageData (no colour conversion) and shows a
  frame with putImageData on a canvas whose backing store is the pattern's
  size in device pixels and whose CSS size is that divided by
  devicePixelRatio: a raw pixel copy, no scaling, no smoothing;
- advances in requestAnimationFrame, holding each loop entry for `hold`
  display refreshes (the start marker for `marker_hold`, a frame kind listed
  in kind_holds for its own: the identity frames can be held shorter than
  the rotating star, pattern.loop.SHORT_HOLDS);
- opens on a check screen: 1-px stripes and checkers that turn grey or show
  beats when the mapping is not 1:1, a one-pixel frame around the screen
  edge that shows cropping, the measured refresh rate, and a warning that
  lists what breaks the mapping (fractional devicePixelRatio, pinch or
  browser zoom, a page or screen size that does not match pattern.json,
  portrait orientation);
- controls: tap / Space / Enter start (full screen where the browser allows
  it); while playing tap or Space pauses; paused, the left / right third of
  the screen or the arrow keys step, the middle third or Space resumes; R
  restarts at the start marker, C or a long press returns to the check
  screen, F toggles full screen, + / - change the hold on the check screen.
  URL options: #hold=N&markerhold=N&play; #hold=N holds every kind N
  refreshes, #identityhold=N (any kind + "hold") one kind.

For tests and remote control the page exposes window.rotstar: ready (a
Promise), show(k) (pause on loop entry k), check(), play(), status().
"""

from __future__ import annotations

import base64
import importlib.resources
import json
import os

from rotstar_mrcal.atomic import atomic_write
from rotstar_mrcal.pattern.layout import layout_from_dict
from rotstar_mrcal.pattern.loop import SHORT_HOLDS, entry_holds, player_loop

TEMPLATE = "player_template.html"
DEFAULT_HOLD = None
"""Display refreshes per loop entry: None, each frame kind its own (pattern.loop.SHORT_HOLDS: a 2.9 s loop of
the default sequence at 60 Hz, which rotstar-capture takes in about 3 s a pose); a number holds every kind that
many refreshes (30, the default before issue 23: 0.5 s at 60 Hz, an 11.5 s loop)"""


def hold_text(hold: int | None) -> str:
    """A hold as --hold takes it

    >>> hold_text(None), hold_text(30)
    ('short', '30')
    """
    return "short" if hold is None else str(hold)


def player_config(pattern: dict, pngs: dict[str, bytes], hold: int | None = DEFAULT_HOLD,
                  marker_hold: int | None = None, kind_holds: dict | None = None) -> dict:
    """The page's configuration: screen size, loop, hold times, embedded PNGs

    pattern: the pattern.json dictionary; pngs: {file name: PNG bytes} for
    every frame of pattern["frames"]. Hold times as pattern.loop.entry_holds
    takes them: hold for every kind (None: loop.SHORT_HOLDS per kind),
    kind_holds {kind: refreshes} over it, marker_hold for the start marker.
    """
    layout = layout_from_dict(pattern)
    loop = player_loop(pattern["frames"])
    holds = entry_holds(loop, hold, kind_holds, marker_hold)
    if holds.min() < 1:
        raise ValueError("hold times must be at least one display refresh")
    general = SHORT_HOLDS["rotstar"] if hold is None else int(hold)
    by_kind = {e["kind"]: int(h) for e, h in zip(loop[1:], holds[1:]) if h != general}
    for e in loop[1:]:
        if e["file"] not in pngs:
            raise ValueError(f"{e['file']}: no PNG for this frame of pattern.json")
    return {
        "format": "rotstar-player/1",
        "width": layout.screen_width,
        "height": layout.screen_height,
        "hold": general,
        "markerHold": int(holds[0]),
        "kindHolds": by_kind,
        "loop": [
            {
                "kind": e["kind"],
                "file": e["file"],
                "src": None if e["file"] is None
                else "data:image/png;base64," + base64.b64encode(pngs[e["file"]]).decode("ascii"),
            }
            for e in loop
        ],
    }


def render_player(config: dict) -> str:
    """The HTML text of the page for a player_config"""
    template = importlib.resources.files(__package__).joinpath(TEMPLATE).read_text(encoding="utf-8")
    blob = json.dumps(config, separators=(",", ":")).replace("</", "<\\/")
    if template.count("/*ROTSTAR-CONFIG*/") != 1:
        raise RuntimeError(f"{TEMPLATE}: the configuration placeholder is missing")
    return template.replace("/*ROTSTAR-CONFIG*/", blob)


def write_player(folder: str, hold: int | None = DEFAULT_HOLD, marker_hold: int | None = None,
                 name: str = "player.html", kind_holds: dict | None = None) -> str:
    """Write folder/player.html from folder/pattern.json and the frame PNGs beside it"""
    with open(os.path.join(folder, "pattern.json")) as f:
        pattern = json.load(f)
    pngs = {}
    for fr in pattern["frames"]:
        with open(os.path.join(folder, fr["file"]), "rb") as f:
            pngs[fr["file"]] = f.read()
    fn = os.path.join(folder, name)
    with atomic_write(fn, encoding="utf-8") as f:
        f.write(render_player(player_config(pattern, pngs, hold, marker_hold, kind_holds)))
    return fn
