"""The methods rotstar is compared against, and the one registry of every method

Modules, one concept each:

    registry      every corner method and refiner, listed once (METHODS,
                  REFINERS): rotstar, its refiners, and the peers below
    checkerboard  OpenCV's SB finder and cornerSubPix, the saddle fit
                  (Lucchese-Mitra), mrgingham
    phase         4-step phase shifting: corners where the fringes take the
                  corner's phases
    charuco       a ChArUco board on the same screen, OpenCV's detector
    cornersets    the corners of one pose by each method

See doc/benchmark.md.
"""
