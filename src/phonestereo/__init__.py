"""phonestereo: metric depth from a phone's wide + tele stereo cameras.

The system of the MSc thesis "From disparity to depth on mobile phone stereo cameras"
(see ``docs/index.md``): calibration, rectification, sub-pixel matching, the chapter-3 fixes,
the chapter-4 flows, and a virtual module that renders captures with ground truth.
"""

__version__ = "0.1.0"
