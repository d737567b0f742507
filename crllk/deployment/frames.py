"""Camera frames for the pilot: read from a folder of images or a video."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from crllk.errors import ConfigError
from crllk.images import check_frame_bytes, check_frame_pixels

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv", ".mov", ".webm")


def read_frames(path: str | Path) -> Iterator[tuple[str, bytes | np.ndarray]]:
    """Named frames from a folder of images (their bytes, in name order: JPEG files reach the
    pilot as the camera's messages do) or from a video (RGB arrays).

    Raises:
        ConfigError: for a missing path, a folder without images, an unreadable video, or a
            file or video frame over the bounds of :mod:`crllk.images` (checked before reading).
    """
    path = Path(path)
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise ConfigError(path, "frames", f"no images ({', '.join(IMAGE_SUFFIXES)})")
        for file in files:
            check_frame_bytes(file.stat().st_size, str(file))
            yield file.name, file.read_bytes()
        return
    if not path.is_file():
        raise ConfigError(path, "frames", "no such folder or video")
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise ConfigError(path, "frames", f"not a folder of images or a video "
                          f"({', '.join(VIDEO_SUFFIXES)})")
    import cv2  # OpenCV reads videos; frames come out BGR

    video = cv2.VideoCapture(str(path))
    if not video.isOpened():
        raise ConfigError(path, "frames", "cannot read the video")
    try:
        check_frame_pixels(int(video.get(cv2.CAP_PROP_FRAME_WIDTH)),
                           int(video.get(cv2.CAP_PROP_FRAME_HEIGHT)), str(path))
        index = 0
        while True:
            ok, frame = video.read()
            if not ok:
                break
            yield f"{path.name}#{index}", cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
            index += 1
    finally:
        video.release()
    if index == 0:
        raise ConfigError(path, "frames", "the video has no frames")
