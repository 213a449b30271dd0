"""Exemplars sent to the page: size limit while they arrive, allowed types, pixels before decoding.

An upload is stored under a name the server makes (``u<random>.png``): no name or path from
the client touches the file system; the client's file name is kept for display and for the
equivalent command line only, cleaned of anything but printable characters
(``docs/web.md``, "Safety"). Every refusal is one line naming the problem and what is
allowed, as on the command line.
"""

from __future__ import annotations

import asyncio
import os
import secrets
import unicodedata
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

from .. import data
from ..errors import InputError
from ..io import check_image_size, read_image, read_image_header, write_image

__all__ = [
    "ALLOWED_TYPES",
    "Exemplar",
    "UploadError",
    "UploadStore",
    "clean_name",
    "sniff_type",
]

#: file types accepted, by their first bytes -> (suffix, name shown in messages)
ALLOWED_TYPES = {
    "png": ".png",
    "jpeg": ".jpg",
    "tiff": ".tif",
    "webp": ".webp",
    "bmp": ".bmp",
}
ALLOWED_TYPE_NAMES = "PNG, JPEG, TIFF, WebP, BMP"


class UploadError(InputError):
    """An upload refused; ``status`` is the HTTP status to answer with."""

    def __init__(self, message: str, status: int = 400):
        super().__init__(message)
        self.status = status


def sniff_type(head: bytes) -> str | None:
    """The type of a file from its first 12 bytes (a key of :data:`ALLOWED_TYPES`), or ``None``."""
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return "png"
    if head.startswith(b"\xff\xd8\xff"):
        return "jpeg"
    if head.startswith((b"II*\x00", b"MM\x00*")):
        return "tiff"
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        return "webp"
    if head.startswith(b"BM"):
        return "bmp"
    return None


def clean_name(name: str | None, limit: int = 80) -> str:
    """A client's file name made safe to show: its last path part, printable characters only."""
    text = (name or "").replace("\\", "/").rsplit("/", 1)[-1]
    text = "".join(ch for ch in text if unicodedata.category(ch)[0] not in "CZ" or ch == " ").strip()
    text = text.lstrip(".")
    return text[:limit] or "exemplar.png"


@dataclass(frozen=True)
class Exemplar:
    """An exemplar the page may use: an upload or a built-in texture.

    Attributes
    ----------
    id : str
        ``u...`` for an upload, ``builtin:NAME`` for a built-in.
    name : str
        How the page and the command line name it (the client's cleaned file name).
    argument : str
        What ``texsyn synth`` is given: the stored file's path or ``builtin:NAME``.
    preview : Path
        A PNG of the exemplar as texsyn reads it, for the page.
    width, height, channels : int
    """

    id: str
    name: str
    argument: str
    preview: Path
    width: int
    height: int
    channels: int

    def public(self) -> dict:
        """What the page is told (no server path)."""
        return {
            "id": self.id,
            "name": self.name,
            "width": self.width,
            "height": self.height,
            "channels": self.channels,
        }


class UploadStore:
    """The uploads and built-in exemplars of one server launch, kept in ``folder``.

    Parameters
    ----------
    folder : Path
        The server's temporary folder for uploads (removed on exit by the server).
    max_bytes, max_pixels : int
        Limits of one upload (:class:`~texsyn.web.settings.ServerSettings`).
    max_uploads : int
        Uploads kept at most in one launch (the disk is not the client's to fill).
    """

    def __init__(self, folder: Path, max_bytes: int, max_pixels: int, max_uploads: int = 200):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.max_bytes = int(max_bytes)
        self.max_pixels = int(max_pixels)
        self.max_uploads = int(max_uploads)
        self.items: dict[str, Exemplar] = {}
        self.arriving = 0  # uploads being received now

    def get(self, exemplar_id: str) -> Exemplar:
        """An upload or a built-in by its id; :class:`UploadError` (404) when unknown."""
        if exemplar_id.startswith("builtin:"):
            return self.builtin(exemplar_id.split(":", 1)[1])
        found = self.items.get(exemplar_id)
        if found is None:
            raise UploadError(
                "unknown exemplar: upload the image again (uploads last until the server stops)", 404
            )
        return found

    def builtin(self, name: str) -> Exemplar:
        """A built-in exemplar (``texsyn.data``), its preview written on first use."""
        if name not in data.BUILTIN:
            raise UploadError(
                f"unknown built-in exemplar {name!r}; choose one of: {', '.join(data.BUILTIN)}", 404
            )
        key = f"builtin:{name}"
        if key not in self.items:
            image = data.exemplar(name)
            preview = self.folder / f"builtin-{name}.png"
            write_image(preview, image)
            height, width = image.shape[:2]
            channels = 1 if image.ndim == 2 else image.shape[2]
            self.items[key] = Exemplar(key, key, key, preview, width, height, channels)
        return self.items[key]

    async def receive(
        self, chunks: AsyncIterator[bytes], client_name: str | None, declared: int | None
    ) -> Exemplar:
        """Store an upload arriving as ``chunks``, check it and decode it once.

        Raises
        ------
        UploadError
            Over the byte limit (413, before reading when the declared length says so),
            empty, not an allowed type (415), too many pixels (413, from the header), or not
            readable (400, e.g. truncated).
        """
        limit_mb = f"{self.max_bytes / 1e6:g} MB"
        if declared is not None and declared > self.max_bytes:
            raise UploadError(f"the file is {declared / 1e6:.1f} MB, over the {limit_mb} upload limit", 413)
        stored = sum(1 for key in self.items if not key.startswith("builtin:"))
        if stored + self.arriving >= self.max_uploads:  # uploads under way count too
            raise UploadError(
                f"this server keeps at most {self.max_uploads} uploads; restart it to start afresh", 507
            )
        self.arriving += 1
        try:
            return await self._receive(chunks, client_name, limit_mb)
        finally:
            self.arriving -= 1

    async def _receive(
        self, chunks: AsyncIterator[bytes], client_name: str | None, limit_mb: str
    ) -> Exemplar:
        """Store the bytes under a server-made name, then check them (:meth:`receive`)."""
        upload_id = "u" + secrets.token_hex(8)
        part = self.folder / f"{upload_id}.part"
        size = 0
        try:
            with open(part, "wb") as fh:
                async for chunk in chunks:
                    size += len(chunk)
                    if size > self.max_bytes:
                        raise UploadError(f"the file is over the {limit_mb} upload limit", 413)
                    fh.write(chunk)
            if size == 0:
                raise UploadError("the file is empty; send an image (" + ALLOWED_TYPE_NAMES + ")")
            with open(part, "rb") as fh:
                kind = sniff_type(fh.read(12))
            if kind is None:
                raise UploadError(
                    f"not an image texsyn accepts here; allowed types: {ALLOWED_TYPE_NAMES}", 415
                )
            path = self.folder / f"{upload_id}{ALLOWED_TYPES[kind]}"
            os.replace(part, path)
        except BaseException:
            part.unlink(missing_ok=True)
            raise
        name = clean_name(client_name)
        try:  # decoding takes a while: off the event loop
            return await asyncio.to_thread(self._check, upload_id, name, path, size)
        except BaseException:
            path.unlink(missing_ok=True)
            raise

    def _check(self, upload_id: str, name: str, path: Path, size: int) -> Exemplar:
        """Header and pixel limit first, then one full decode (a truncated file shows here)."""
        try:
            header = read_image_header(path)
            check_image_size(header, path, max_pixels=self.max_pixels, file_size=size)
            image = read_image(path)
        except InputError as exc:
            message = str(exc).replace(str(path), name).replace(path.name, name)
            status = 413 if "pixels" in message and ("more than" in message or "bomb" in message) else 400
            raise UploadError(message, status) from None
        preview = self.folder / f"{upload_id}.preview.png"
        write_image(preview, image)
        height, width = image.shape[:2]
        channels = 1 if image.ndim == 2 else image.shape[2]
        found = Exemplar(upload_id, name, str(path), preview, width, height, channels)
        self.items[upload_id] = found
        return found
