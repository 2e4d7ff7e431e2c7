"""What rotstar-capture's exposure look does on the simulated camera: from a few starting exposures, the exposure
chosen, the looks taken, the seconds at the screen they cost, and the white reached

The capture's simulated camera (capture.simulated.SimulatedCamera: the light scales with the exposure, the
screen's white irradiance at full scale at 13.3 ms, noise 1 %) films the looping player of the default 800 x 600
test pattern (20 entries, the short holds) from random poses, clean and with every timing flaw
(simulated.ALL_FLAWS: a 480 Hz PWM backlight at 60 % duty among them), at 25 fps; choose_exposure runs as
rotstar-capture runs it (8 settle frames after each change, looks of look_frames() frames, 20 us to 38 ms).
'true white' is the white a look would measure without noise, clipping or flaws at the chosen exposure (the
sensor is linear); the target is 75 %.

    .venv/bin/python scripts/exposure_look_bench.py [--poses 3] [--camera pinhole-small]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from rotstar_mrcal import simulate
from rotstar_mrcal.capture.exposure import SHORTEST_US, choose_exposure, longest_exposure_us, look_frames, measure_look
from rotstar_mrcal.capture.simulated import ALL_FLAWS, Flaws, SimulatedCamera, loop_irradiance
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.pattern.loop import entry_holds, player_loop

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
STARTS = (500, 4000, 30000)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--poses", type=int, default=3)
    p.add_argument("--camera", default="pinhole-small", help="a simulate preset (default pinhole-small, 640x400)")
    a = p.parse_args(argv)
    model = simulate.preset_model(a.camera)
    holds = entry_holds(player_loop(LAYOUT.frames()))
    print("| pose | flaws | start us | chosen us | looks | s at the screen | white (look) | true white |")
    print("|---|---|---|---|---|---|---|---|")
    for k, rt in enumerate(simulate.random_poses(model, LAYOUT, a.poses, np.random.default_rng(3))):
        E = loop_irradiance(LAYOUT, model, rt)
        white1 = measure_look(E * 65535.0, 65535.0).white  # noise-free white at irradiance gain 1
        for name, flaws in (("none", Flaws()), ("all", ALL_FLAWS)):
            for start in STARTS:
                cam = SimulatedCamera(E, holds, flaws=flaws, seed=[k, start])
                got = choose_exposure(cam, start, look_frames(holds, 60, cam.fps), 8, SHORTEST_US,
                                      longest_exposure_us(cam.fps))
                true = white1 * got.exposure_us / cam.full_scale_us
                print(f"| {k} | {name} | {start} | {got.exposure_us:.0f} | {got.looks} | {got.seconds:.2f} | "
                      f"{got.white:.1%} | {true:.1%} |" if not got.failure else f"| {k} | {name} | {start} | "
                      f"{got.failure} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
