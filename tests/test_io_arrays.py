"""NumPy files from anyone (texsyn.io.arrays): header first, one line, nothing allocated.

The flow files of ``texsyn synth --flow FILE.npy`` go through :func:`texsyn.io.arrays.load_npy`;
model files through :class:`texsyn.io.arrays.NpzArchive` (``tests/test_persistence.py``).
"""

from __future__ import annotations

import io
import os
import tracemalloc

import numpy as np
import pytest
from PIL import Image

import texsyn
from texsyn.cli import main
from texsyn.errors import InputError
from texsyn.io.arrays import load_npy


def npy_bytes(shape, dtype="<f8", data: bytes = b"") -> bytes:
    """An .npy file whose header declares ``shape`` and ``dtype``, followed by ``data``."""
    buffer = io.BytesIO()
    header = {"descr": dtype, "fortran_order": False, "shape": tuple(shape)}
    np.lib.format.write_array_header_1_0(buffer, header)
    return buffer.getvalue() + data


@pytest.mark.parametrize(
    "content,message",
    [
        (npy_bytes((10**6, 10**6, 2)), "truncated or forged"),
        (npy_bytes((4, 4, 2), "|O"), "Python objects"),
        (npy_bytes((4, 4, 2), [("a", "<f8"), ("b", "<f8")]), "data type"),
        (b"\x89PNG\r\n\x1a\n" + b"\0" * 64, "not a flow array"),
        (b"", "not a flow array"),
        (b"\x93NUMPY\x01\x00" + b"\x10\x00" + b"{" * 16, "not a flow array"),
    ],
)
def test_hostile_npy_is_refused_in_one_line_without_allocating(tmp_path, content, message):
    path = tmp_path / "flow.npy"
    path.write_bytes(content)
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match=message) as caught:
            load_npy(path, "a flow array")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert "\n" not in str(caught.value) and "pickle" not in str(caught.value)
    assert peak < 8 * 2**20


def test_a_pipe_or_a_folder_is_refused_at_once(tmp_path):
    fifo = tmp_path / "flow.npy"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="not a regular file"):
        load_npy(fifo, "a flow array")
    with pytest.raises(InputError, match="folder"):
        load_npy(tmp_path, "a flow array")


def test_an_honest_array_loads_unchanged(tmp_path):
    flow = np.random.default_rng(0).standard_normal((8, 6, 2))
    np.save(tmp_path / "flow.npy", flow)
    np.testing.assert_array_equal(load_npy(tmp_path / "flow.npy"), flow)


def test_the_cli_refuses_a_bomb_flow_file_with_exit_2(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    brick = texsyn.data.exemplar("brick", size=32)
    Image.fromarray((brick * 255).astype(np.uint8)).save("ex.png")
    (tmp_path / "bomb.npy").write_bytes(npy_bytes((10**6, 10**6, 2)))
    code = main(["synth", "ex.png", "-o", "out.png", "-m", "grouplets", "--flow", "bomb.npy", "--seed", "0"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "bomb.npy" in err
    assert not (tmp_path / "out.png").exists()
