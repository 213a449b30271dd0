"""Videos through ffmpeg: MP4 (H.264) and WebM (VP9), exit status and output checked.

imageio's writer ignores ffmpeg's exit status (a full disk gave a corrupt file and no
error), so texsyn drives the ffmpeg of imageio-ffmpeg itself and reads the frame count back
from the file it wrote. One writer serves every container; :data:`VIDEO_CODECS` holds what
differs between them (ffmpeg's output options, whether the sides must be even).
"""

from __future__ import annotations

import errno
import os
import subprocess
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from ..errors import InputError
from .encoders import to_uint8

__all__ = ["VIDEO_CODECS", "FfmpegWriter", "VideoCodec", "count_video_frames", "encode_video", "ffmpeg_exe"]


def ffmpeg_exe() -> str:
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


@dataclass(frozen=True)
class VideoCodec:
    """How ffmpeg encodes one video container.

    Attributes
    ----------
    name : str
        The codec, for messages and documentation.
    options : tuple of str
        ffmpeg's output options: codec, pixel format, quality and container (``-f``).
    even_size : bool
        The codec needs even sides: odd sizes are padded by one edge row or column.
    """

    name: str
    options: tuple[str, ...]
    even_size: bool


#: the ffmpeg encoding of each video suffix (imageio-ffmpeg's ffmpeg has both encoders):
#: H.264 at CRF 10 (near lossless; yuv420p needs even sides), and VP9 in constant-quality
#: mode (CRF 15 with ``-b:v 0``: the PSNR of CRF 10 within 0.15 dB at two thirds of the size
#: on a moving colour texture; ``-cpu-used 4 -row-mt 1`` encode 1.5 times as fast as
#: ``-cpu-used 2`` for 0.02 dB; VP9 takes odd sides)
VIDEO_CODECS = {
    ".mp4": VideoCodec(
        "H.264", ("-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "10", "-f", "mp4"), even_size=True
    ),
    ".webm": VideoCodec(
        "VP9",
        (
            "-c:v",
            "libvpx-vp9",
            "-pix_fmt",
            "yuv420p",
            "-crf",
            "15",
            "-b:v",
            "0",
            "-deadline",
            "good",
            "-cpu-used",
            "4",
            "-row-mt",
            "1",
            "-f",
            "webm",
        ),  # fmt: skip
        even_size=False,
    ),
}


class FfmpegWriter:
    """A video (:data:`VIDEO_CODECS`) through an ffmpeg process whose exit status and messages are checked.

    imageio's writer ignores ffmpeg's exit status (a full disk gave a corrupt file and no
    error), so texsyn drives ffmpeg itself: frames go to its stdin as raw RGB, its messages
    to an anonymous temporary file, and any failure raises ``OSError`` with ffmpeg's reason.

    Parameters
    ----------
    path : Path
        The file to write (a temporary: its suffix does not choose the format).
    fps : float
    executable : str, optional
        The ffmpeg to run; imageio-ffmpeg's by default.
    codec : VideoCodec, optional
        The encoding; H.264 MP4 by default.
    """

    def __init__(
        self, path: Path, fps: float, executable: str | None = None, *, codec: VideoCodec | None = None
    ) -> None:
        self.path = Path(path)
        self.executable = executable
        self.codec = VIDEO_CODECS[".mp4"] if codec is None else codec
        self.fps = Fraction(fps).limit_denominator(1001)
        self.count = 0
        self.size: tuple[int, int] | None = None
        self._proc: subprocess.Popen | None = None
        self._log = tempfile.TemporaryFile()

    def _start(self, h: int, w: int) -> None:
        cmd = [
            self.executable or ffmpeg_exe(), "-y", "-v", "error", "-nostats",
            "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}", "-r", str(self.fps), "-i", "-",
            "-an", *self.codec.options, str(self.path),
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
        if self.codec.even_size:
            h, w = data.shape[:2]
            data = np.pad(data, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
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


def encode_video(
    tmp: Path, frames: Iterable[np.ndarray], fps: float, codec: VideoCodec, *, executable: str | None = None
) -> None:
    """Write ``frames`` as a video encoded by ``codec`` (one of :data:`VIDEO_CODECS`) at ``tmp``.

    ``executable``: the ffmpeg to run (by default imageio-ffmpeg's). ffmpeg's exit status
    and the frame count read back are checked; nothing is left running on an error or an
    interruption.
    """
    writer = FfmpegWriter(tmp, fps, executable, codec=codec)
    try:
        for frame in frames:
            writer.append(frame)
        writer.close()
    except BaseException:
        writer.abort()
        raise
