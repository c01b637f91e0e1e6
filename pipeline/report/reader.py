"""What a report reads from a results folder, turned into what its page shows: JSON content, pictures as PNG
data URIs, links relative to the page. The :class:`Reader` keeps the files read (the report's manifest
inputs), the problems met (files missing or unreadable) and the number of pictures embedded."""

from __future__ import annotations

import base64
import io
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..artifacts import read_json
from ..imageio import png_bytes, read_image

MAX_IMAGE_WIDTH = 1200  # pixels; wider pictures are shrunk before embedding


def png_data_uri(image: np.ndarray, max_width: int = MAX_IMAGE_WIDTH) -> str:
    """``(H, W)`` / ``(H, W, 3|4)`` uint8, uint16 or [0, 1] float array in RGB(A) order ->
    ``data:image/png;base64,...``, shrunk to ``max_width`` wide."""
    import cv2

    image = np.asarray(image)
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    elif image.dtype != np.uint8:
        image = np.round(np.clip(image, 0, 1) * 255).astype(np.uint8)
    if image.shape[1] > max_width:
        h = max(1, round(image.shape[0] * max_width / image.shape[1]))
        image = cv2.resize(image, (max_width, h), interpolation=cv2.INTER_AREA)
    return "data:image/png;base64," + base64.b64encode(png_bytes(image)).decode("ascii")


def figure_data_uri(fig) -> str:
    """A matplotlib figure as a PNG data URI."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


@dataclass(frozen=True)
class Picture:
    """A picture on the page: its data URI, or the sentence said instead (``missing``: the file that is not
    there; ``error``: why it could not be read); none of them for an optional picture that is absent."""

    uri: str = ""
    alt: str = ""
    caption: str | None = None
    css: str | None = None
    missing: str | None = None
    error: str | None = None


@dataclass(frozen=True)
class Link:
    """A file the page links to rather than embeds: ``href`` relative to the page, None when the file is missing;
    ``path`` as the page prints it (relative to the results folder when missing); ``size`` in words, or empty."""

    href: str | None
    text: str
    path: str
    size: str = ""


@dataclass
class Reader:
    """Reads a results folder for a page written into ``out_dir``."""

    results: Path
    out_dir: Path
    inputs: dict[str, Path] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    images: int = 0

    def json(self, path: Path, required: bool = True) -> Any:
        """A JSON file's content, recorded as an input; None (and a problem noted if ``required``) when absent
        or unreadable."""
        if not path.is_file():
            if required:
                self.problems.append(f"{self.rel(path)} is missing")
            return None
        try:
            data = read_json(path)
        except (OSError, ValueError) as e:
            self.problems.append(f"{self.rel(path)} could not be read: {e}")
            return None
        self.record(path)
        return data

    def record(self, path: Path) -> None:
        """Name ``path`` among the inputs."""
        self.inputs[self.rel(path)] = path

    def picture(self, path: Path, caption: str | None = None, *, alt: str | None = None, width: int | None = None,
                required: bool = True, css: str | None = None) -> Picture:
        """The picture at ``path``, at most ``width`` wide (or why it is not shown)."""
        if not path.is_file():
            if required:
                self.problems.append(f"{self.rel(path)} is missing")
                return Picture(missing=self.rel(path))
            return Picture()
        try:
            uri = png_data_uri(read_image(path), min(width or MAX_IMAGE_WIDTH, MAX_IMAGE_WIDTH))
        except (OSError, ValueError) as e:
            self.problems.append(f"{self.rel(path)} could not be read: {e}")
            return Picture(error=f"{self.rel(path)} could not be read: {e}")
        self.images += 1
        return Picture(uri=uri, alt=alt or caption or path.name, caption=caption, css=css)

    def figure(self, fig, caption: str) -> Picture:
        """A matplotlib figure."""
        self.images += 1
        return Picture(uri=figure_data_uri(fig), alt=caption, caption=caption)

    def link(self, path: Path, text: str | None = None) -> Link:
        """A link to ``path`` relative to the page, with the file's size when it is worth saying."""
        if not path.exists():
            return Link(None, text or path.name, self.rel(path))
        href = Path(os.path.relpath(path.resolve(), self.out_dir.resolve())).as_posix()
        size = path.stat().st_size if path.is_file() else None
        extra = f" ({size / 1e6:.2f} MB)" if size is not None and size >= 1e5 else (
            f" ({size} bytes)" if size is not None else "")
        return Link(href, text or path.name, str(path), extra)

    def rel(self, path: Path) -> str:
        """``path`` relative to the results folder (as it is when outside it)."""
        try:
            return Path(path).relative_to(self.results).as_posix()
        except ValueError:
            return str(path)
