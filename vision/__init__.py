"""Images → sun: camera models, detection, synthetic frames, calibration, metrics.

A plain library (OpenCV, numpy, scipy; nothing else of ours): ``cameras``
(pinhole and fisheye, pixel ↔ direction), ``detect`` (the robust detector and
the seeds' pipelines), ``synth`` (frames with a known sun), ``calibrate``
(fisheye fit against an ephemeris), ``metrics`` (seed 003's error metrics) and
``imageio`` (header-checked decoding).
"""
