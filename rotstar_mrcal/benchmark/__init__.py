"""The benchmark (`make bench`, scripts/bench.py): rotstar against OpenCV and mrgingham on simulated poses

SYNOPSIS

    from rotstar_mrcal.benchmark import scene, detection, scoring, tables
    sc = scene.make_scene(npose=4, seed=0, bits=16)
    poses = scene.render_all(sc, jobs=2)
    run = detection.detect_all(sc, poses, "/tmp/b")        # every method, timed on one CPU
    summary = scoring.summaries(run.results, sc)
    print(tables.accuracy_table(summary, run.memory))

Modules, one concept each (the methods themselves: rotstar_mrcal.methods):

    scene        camera, layouts, poses; the rendered images of a pose
    scoring      a board against the truth, per-pose rows, summaries, goals
    timing       one pinned CPU, CPU and wall time of a call
    memory       the peak memory of one call, in a fresh process
    detection    every method on every pose, timed, scored, then memory
    calibration  each method's boards calibrated with mrcal, against the true camera
    tables       the Markdown tables and bench.json
    plots        the corner error CDF

See doc/benchmark.md for what is measured and how.
"""
