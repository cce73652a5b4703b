"""Frame sources: image sequences (``cv2.imread``), video files (``cv2.VideoCapture``) and in-memory frames.

Every source hands out grey frames by the camera's own frame index i (0-based for videos; for image
sequences the number in each file name). A frame that does not exist (a dropped frame: a missing file
in a sequence) is ``None``.

Image sequences are given as a printf pattern (``cam1/img_%05d.png``), a glob (``cam1/*.png``; the
frame number is the last integer in the file name) or a folder (every image file in it).
"""
from __future__ import annotations

import glob as globmod
import re
from pathlib import Path

import cv2
import numpy as np

from .errors import VideoInputError

IMAGE_SUFFIXES = {".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg", ".pgm", ".ppm"}
VIDEO_SUFFIXES = {".avi", ".mp4", ".mov", ".mkv", ".m4v", ".mpg", ".mpeg", ".wmv"}


def to_gray(img: np.ndarray) -> np.ndarray:
    """Grey version of a frame (colour frames are converted with OpenCV's BGR weights)."""
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 1:
        return img[..., 0]
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
    raise ValueError(f"unsupported frame shape {img.shape}")


class ImageSequence:
    """Numbered image files. ``files`` maps frame index → path."""

    def __init__(self, files: dict[int, Path], description: str = ""):
        if not files:
            raise VideoInputError(f"{description}: no image files found")
        self.files = dict(sorted(files.items()))
        self.description = description
        self.first, self.last = min(self.files), max(self.files)

    @classmethod
    def from_spec(cls, spec: str, base: Path | None = None) -> "ImageSequence":
        p = Path(spec)
        if not p.is_absolute() and base is not None:
            p = base / p
        text = str(p)
        files: dict[int, Path] = {}
        if "%" in text:
            folder = p.parent
            m = re.search(r"%0?(\d*)d", p.name)
            if not m:
                raise VideoInputError(f"{spec}: a printf pattern needs a %d or %0Nd field")
            rx = re.compile("^" + re.escape(p.name[:m.start()]) + r"(\d+)" + re.escape(p.name[m.end():]) + "$")
            if not folder.is_dir():
                raise VideoInputError(f"{spec}: folder {folder} not found")
            for f in folder.iterdir():
                mm = rx.match(f.name)
                if mm:
                    files[int(mm.group(1))] = f
        elif any(ch in text for ch in "*?["):
            for f in globmod.glob(text):
                files.setdefault(*_numbered(Path(f)))
        elif p.is_dir():
            for f in p.iterdir():
                if f.suffix.lower() in IMAGE_SUFFIXES:
                    k, path = _numbered(f)
                    if k in files:
                        raise VideoInputError(f"{spec}: files {files[k].name} and {f.name} have the same frame number {k}")
                    files[k] = path
        else:
            raise VideoInputError(f"{spec}: not found (give a video file, a folder, a glob or a printf pattern)")
        if not files:
            raise VideoInputError(f"{spec}: no image files match")
        return cls(files, spec)

    def frame_range(self) -> tuple[int, int]:
        return self.first, self.last

    def get(self, i: int):
        path = self.files.get(int(i))
        if path is None:
            return None
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise VideoInputError(f"{path}: cannot be read as an image")
        return to_gray(img)

    def close(self) -> None:
        pass


def _numbered(f: Path) -> tuple[int, Path]:
    nums = re.findall(r"\d+", f.stem)
    if not nums:
        raise VideoInputError(f"{f}: image file name has no frame number")
    return int(nums[-1]), f


class VideoFile:
    """A video read sequentially with ``cv2.VideoCapture``; frames are numbered from 0."""

    def __init__(self, path, description: str = ""):
        self.path = Path(path)
        if not self.path.is_file():
            raise VideoInputError(f"{path}: video file not found")
        self.cap = cv2.VideoCapture(str(self.path))
        if not self.cap.isOpened():
            raise VideoInputError(f"{path}: OpenCV cannot open this video")
        n = int(self.cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.n_frames = n if n > 0 else None
        self.next_index = 0
        self.description = description or str(path)

    def frame_range(self) -> tuple[int, int]:
        if self.n_frames is None:
            raise VideoInputError(f"{self.path}: frame count unknown; give 'frames' in the track config")
        return 0, self.n_frames - 1

    def get(self, i: int):
        i = int(i)
        if i < 0 or (self.n_frames is not None and i >= self.n_frames):
            return None
        if i < self.next_index:
            self.cap.set(cv2.CAP_PROP_POS_FRAMES, i)
            self.next_index = i
        while self.next_index < i:
            if not self.cap.grab():
                return None
            self.next_index += 1
        ok, img = self.cap.read()
        if not ok:
            return None
        self.next_index += 1
        return to_gray(img)

    def close(self) -> None:
        self.cap.release()


class ArrayFrames:
    """In-memory or generated frames: ``getter(i)`` returns a frame or None; frames ``first..last``."""

    def __init__(self, getter, first: int, last: int, description: str = "frames"):
        self.getter, self.first, self.last, self.description = getter, int(first), int(last), description

    def frame_range(self) -> tuple[int, int]:
        return self.first, self.last

    def get(self, i: int):
        if i < self.first or i > self.last:
            return None
        return self.getter(int(i))

    def close(self) -> None:
        pass


def open_source(spec: str, base: Path | None = None):
    """A frame source from a config string: a video file, or an image sequence (pattern, glob, folder)."""
    p = Path(spec)
    if not p.is_absolute() and base is not None:
        p = base / p
    if p.suffix.lower() in VIDEO_SUFFIXES and "%" not in str(p) and not any(ch in str(p) for ch in "*?["):
        return VideoFile(p, spec)
    return ImageSequence.from_spec(spec, base)
