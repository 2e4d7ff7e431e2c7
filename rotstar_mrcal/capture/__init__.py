"""Recording the screen: camera backends, the D435 preset, splitting a recording into frames

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.capture.source import ArraySource, record
    >>> from rotstar_mrcal.capture.segment import threshold, stable_runs
    >>> rec = record(ArraySource(np.zeros((6, 4, 4), np.uint8)), 6)
    >>> rec.frames.shape, rec.full_scale
    ((6, 4, 4), 255.0)

Modules, one concept each:

    v4l2               the V4L2 ioctl layer: structures, format negotiation,
                       controls, mmap streaming; all system calls behind
                       Syscalls (tests substitute a fake device)
    uvc_xu             UVC extension-unit queries (UVCIOC_CTRL_QUERY); the
                       D4xx depth unit's selectors
    d435               the D435 preset: find the IR node by USB id and
                       formats, Y16 1280x800 by default, exposure in us and
                       the emitter through the extension unit
    interleaved        the D4xx stereo formats: Y12I / Y8I -> left and right
                       images (the Y12I bit layout is one named switch)
    colour             a colour node's frames (YUYV, UYVY, MJPG) as grey
    source             FrameSource (what a backend is), Frame, record()
    backend_v4l2       a V4L2 node as a FrameSource (the default backend)
    backend_libcamera  libcamera's `cam` tool as a FrameSource (experimental)
    backend_realsense  pyrealsense2 as a FrameSource (optional)
    backend_replay     a recording (folder of frames, .npy, .raw, video)
    backends           open a backend by name
    motion             frame differences, stillness, affine drift
    exposure           the exposure from a short look at the playing screen
                       (the pattern's white at 75 % of full scale)
    segment            a recording of the looping player -> its frames
    rig                several cameras read in lockstep (RigSource, record_rig)
    rig_segment        every camera's recording split with the same frame
                       boundaries, checked on each camera
    rig_session        a pose of several cameras -> <pose>/camera-<k>/ folders
    pose               one pose: segmented frames -> dataset folder, quick check
    coverage           which parts of the imager the detected corners cover
    simulated          simulated recordings of the player, and a simulated
                       camera (SimulatedCamera) whose exposure can be set

See doc/capture.md.
"""
