"""The display sequence: its geometry, its frames, the identity codes and the player

SYNOPSIS

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.pattern.loop import player_loop
    >>> [e["kind"] for e in player_loop(make_layout(screen=(800, 600), pitch=100, band=24).frames())][:3]
    ['start-marker', 'rotstar', 'rotstar']

Modules, one concept each:

    layout    geometry of the rotating-star sequence and the pattern.json
              contract
    render    exact rendering of the display frames
    identity  identity codes: each element's grid index written in time
    loop      the loop the player shows: a start marker, then pattern.json's
              frames; the mean luminance of every entry
    player    player.html: the loop at one PNG pixel per device pixel, with a
              check screen

See doc/pattern.md and doc/capture.md.
"""
