"""What the screen shows: the looping player of the display sequence

SYNOPSIS

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.display import player_loop
    >>> [e["kind"] for e in player_loop(make_layout(screen=(800, 600), pitch=100, band=24).frames())][:3]
    ['start-marker', 'rotstar', 'rotstar']

Modules, one concept each:

    loop     the loop the player shows: a start marker, then pattern.json's
             frames; the mean luminance of every entry (what segmentation
             checks the recorded order against)
    player   player.html: one self-contained page that plays the loop at one
             PNG pixel per device pixel, with a check screen

See doc/capture.md.
"""

from .loop import MARKER, expected_levels, player_loop
from .player import player_config, render_player, write_player

__all__ = ["MARKER", "expected_levels", "player_loop", "player_config", "render_player", "write_player"]
