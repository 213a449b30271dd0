"""MP4 videos: H.264 through an ffmpeg process whose exit status and output are checked.

imageio's writer ignores ffmpeg's exit status (a full disk gave a corrupt file and no
error), so texsyn drives the ffmpeg of imageio-ffmpeg itself and reads the frame count back
from the file it wrote.
"""

from __future__ import annotations

import errno
import os
import subprocess
import tempfile
from collections.abc import Iterable
from fractions import Fraction
from pathlib import Path

import numpy as np

from ..errors import InputError
from .encoders import to_uint8

__all__ = ["FfmpegWriter", "count_video_frames", "encode_mp4", "ffmpeg_exe"]


def ffmpeg_exe() -> str:
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


class FfmpegWriter:
    """H.264 MP4 through an ffmpeg process whose exit status and messages are checked.

    imageio's writer ignores ffmpeg's exit status (a full disk gave a corrupt file and no
    error), so texsyn drives ffmpeg itself: frames go to its stdin as raw RGB, its messages
    to an anonymous temporary file, and any failure raises ``OSError`` with ffmpeg's reason.
    """

    def __init__(self, path: Path, fps: float, executable: str | None = None) -> None:
        self.path = Path(path)
        self.executable = executable
        self.fps = Fraction(fps).limit_denominator(1001)
        self.count = 0
        self.size: tuple[int, int] | None = None
        self._proc: subprocess.Popen | None = None
        self._log = tempfile.TemporaryFile()

    def _start(self, h: int, w: int) -> None:
        cmd = [
            self.executable or ffmpeg_exe(), "-y", "-v", "error", "-nostats",
            "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}", "-r", str(self.fps), "-i", "-",
            "-an", "-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "10",
            "-f", "mp4", str(self.path),
        ]  # fmt: skip
        self._proc = subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            stderr=self._log,
            start_new_session=True,  # Ctrl-C reaches texsyn only; texsyn stops ffmpeg itself
        )
        self.size = (h, w)

    def append(self, frame: np.ndarray) -> None:
        data = to_uint8(frame)
        if data.ndim == 2:
            data = np.repeat(data[..., None], 3, axis=2)
        elif data.shape[2] == 4:
            data = data[..., :3]
        h, w = data.shape[:2]
        data = np.pad(data, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")  # yuv420p needs even sizes
        if self._proc is None:
            self._start(*data.shape[:2])
        elif data.shape[:2] != self.size:
            raise InputError(
                f"every frame must have the size of the first, {self.size}, got {data.shape[:2]}"
            )
        assert self._proc is not None and self._proc.stdin is not None
        try:
            self._proc.stdin.write(np.ascontiguousarray(data).tobytes())
        except OSError:  # ffmpeg stopped reading (it failed): report its reason
            self._finish()
            raise self._failure() from None
        self.count += 1

    def _finish(self) -> int:
        proc = self._proc
        assert proc is not None
        if proc.stdin is not None:
            try:
                proc.stdin.close()
            except OSError:
                pass
        return proc.wait()

    def _failure(self) -> OSError:
        self._log.seek(0)
        text = self._log.read().decode("utf-8", "replace")
        lines = [line.strip() for line in text.splitlines() if line.strip()]
        code = self._proc.returncode if self._proc is not None else None
        if "No space left on device" in text:
            return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        if "Permission denied" in text:
            return OSError(errno.EACCES, os.strerror(errno.EACCES))
        reason = lines[-1] if lines else f"exit status {code}"
        return OSError(errno.EIO, f"ffmpeg failed: {reason}")

    def close(self) -> None:
        """Wait for ffmpeg; raise ``OSError`` unless it succeeded and the file holds every frame."""
        try:
            if self._proc is None:
                raise InputError("no frames to write")
            if self._finish() != 0:
                raise self._failure()
            if self.path.stat().st_size == 0:
                raise OSError(errno.EIO, "ffmpeg wrote an empty file")
            written = count_video_frames(self.path)
            if written != self.count:
                raise OSError(errno.EIO, f"the video holds {written} of {self.count} frames")
        finally:
            self._log.close()

    def abort(self) -> None:
        """Stop ffmpeg at once (on an error or an interruption)."""
        proc = self._proc
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()
        if proc is not None and proc.stdin is not None:
            try:
                proc.stdin.close()
            except OSError:
                pass
        self._log.close()


def count_video_frames(path: Path) -> int:
    import imageio_ffmpeg

    try:
        frames, _ = imageio_ffmpeg.count_frames_and_secs(str(path))
    except (RuntimeError, OSError) as exc:
        raise OSError(
            errno.EIO, f"the video written cannot be read back ({' '.join(str(exc).split())[:200]})"
        ) from None
    return int(frames)


def encode_mp4(tmp: Path, frames: Iterable[np.ndarray], fps: float, *, executable: str | None = None) -> None:
    """Write ``frames`` as an H.264 MP4 at ``tmp``; ``executable``: the ffmpeg to run (by
    default imageio-ffmpeg's). Nothing is left running on an error or an interruption."""
    writer = FfmpegWriter(tmp, fps, executable)
    try:
        for frame in frames:
            writer.append(frame)
        writer.close()
    except BaseException:
        writer.abort()
        raise
