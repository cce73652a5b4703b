"""Video front end: multi-camera footage (or files of other digitising tools) → marker tracks (docs/data-formats.md).

Modules, one job each:

- :mod:`.camera` — pinhole camera with OpenCV lens distortion (projection, undistortion);
- :mod:`.calibration` — 11-parameter DLT from control points, decomposition to K, R, t, and camera
  files (bayes-disc YAML, DLT coefficient CSVs of DLTdv/Argus/easyWand, anipose ``calibration.toml``);
- :mod:`.footage` — frames from videos (``cv2.VideoCapture``) and image sequences (``cv2.imread``);
- :mod:`.detection` — blob detection and intensity-weighted centroids;
- :mod:`.triangulation` — N-view linear DLT + Gauss–Newton triangulation with covariance;
- :mod:`.identity` — marker labelling on the scalene triangle and rigid-body prediction;
- :mod:`.imports` — DLTdv and Argus 2-D/3-D point files;
- :mod:`.render` — synthetic multi-camera footage of a simulated flight, with ground truth;
- :mod:`.pipeline` — ``TRACK.yaml`` → marker file; :mod:`.cli` — ``track`` and ``render`` commands.
"""
from .errors import VideoInputError

__all__ = ["VideoInputError"]
