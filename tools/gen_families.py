#!/usr/bin/env python3
"""Generate the Rust code tables of touchdown's marker families.

Usage
-----
Shipped families (writes core/src/family/tables/*.rs, then runs rustfmt on them)::

    python3 tools/gen_families.py [--families DIR] [--out-dir DIR] [--check]

  --families DIR  the family text files (default: $TOUCHDOWN_DATA/families, else
                  <repo>/../shared/data/families)
  --out-dir DIR   where the tables go (default: <repo>/core/src/family/tables)
  --check         write nothing; exit 1 if a generated file differs from the one on disk

One user family (a family text file, e.g. a one-line custom 8x8 marker)::

    python3 tools/gen_families.py --user FILE [--name NAME] [--static IDENT] --out PATH
                                  [--crate-path PATH]

  --name NAME        family name stored in the table (default: `# family`, else file stem)
  --static IDENT     the static's identifier (default: USER_FAMILY)
  --crate-path PATH  how the output file names the core crate: `crate` inside
                     touchdown-core, `touchdown_core` elsewhere (default: chosen from --out)

What it does
------------
Every `*.txt` family file is read and laid out exactly as touchdown-core does it
(`core/src/family/mod.rs` and `parse.rs`): the quiet rings are the leading rings white in
every code, the border ring is the first ring black in every code (that leaves more than
2x2 cells inside), a family with data outside its border ("reversed", tagStandard41h12)
must have an all-white ring just inside the border, and every other cell is a data bit,
row-major, the first data cell being the most significant bit. The script then

* checks the `# data_bits` / `# cells` / `# codes` headers against the layout and codes;
* computes the true minimum Hamming distance (between any two codes in all four relative
  rotations, and between each code and its own rotations, like `min_hamming_of`), checks
  it against `# min_hamming` (a mismatch is reported loudly; the computed value is used);
* computes `max_correction` with the same formula as `max_correction_for`;
* adds `aruco_original` (OpenCV's DICT_ARUCO_ORIGINAL, not among the shared files) from
  opencv-contrib-python: `generateImageMarker(dict, id, 7, borderBits=1)` gives the 7x7
  cells, one white quiet ring makes the 9x9 grid the other 5x5 families use;
* cross-checks the shipped ArUco families (and OpenCV's AprilTag dictionaries, which are
  the shared grids turned by 180 degrees) against OpenCV and prints the result;
* builds, for each family that corrects bits, the multi-index of corrected look-ups
  (`core/src/family/index.rs`): the data bits split into more chunks than the correction
  bound, one bucket table per chunk; `choose_chunks` picks the chunk count that balances
  flash against look-up cost, and none when scanning the codes is as cheap (tiny families);
* writes one Rust file per family and `mod.rs` (with `ALL`, `DEFAULT`, `by_name`, `names`
  and the unit tests), and runs `rustfmt --edition 2021` on the files it wrote.

Requires python3 with numpy; opencv-contrib-python (cv2.aruco) for the shipped tables.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
MAX_GRID = 16
MAX_BITS = 64
MAX_FALSE_ACCEPT = 1e-4  # core::family::MAX_FALSE_ACCEPT

# The contract's family names (docs/interfaces.md, "Family names"), in contract order.
CONTRACT_NAMES = (
    ["tag16h5", "tag25h9", "tag36h10", "tag36h11"]
    + [f"aruco_{n}x{n}_{m}" for n in (4, 5, 6, 7) for m in (50, 100, 250, 1000)]
    + ["aruco_mip_36h12", "aruco_original"]
)
# Families the CLI uses without --family.
DEFAULT_NAMES = ["tag36h11", "aruco_6x6_250"]
# Generated from OpenCV rather than read from a file.
OPENCV_ONLY = {"aruco_original": "DICT_ARUCO_ORIGINAL"}


class GenError(Exception):
    pass


def loud(msg: str) -> None:
    bar = "!" * 78
    print(f"{bar}\n!!! {msg}\n{bar}", file=sys.stderr)


# --------------------------------------------------------------------------------------
# Parsing and layout (mirrors core/src/family/parse.rs)
# --------------------------------------------------------------------------------------


@dataclass
class Parsed:
    name: str | None  # `# family`
    grid: int
    headers: dict[str, str]
    grids: np.ndarray  # (count, n, n) bool, True = white
    source: str


def parse_text(text: str, source: str) -> Parsed:
    name = None
    grid = None
    headers: dict[str, str] = {}
    rows: list[str] = []
    for line_no, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            words = line[1:].split()
            if len(words) == 2:
                key, value = words
                headers[key] = value
                if key == "family":
                    name = value
                elif key == "cells":
                    try:
                        n = int(value)
                    except ValueError:
                        raise GenError(f"{source}:{line_no}: bad `# cells` value {value!r}")
                    if not 3 <= n <= MAX_GRID:
                        raise GenError(f"{source}:{line_no}: grid size {n} out of 3..=16")
                    if grid is not None and grid != n:
                        raise GenError(f"{source}:{line_no}: `# cells` disagrees with the codes")
                    grid = n
                elif key == "min_hamming":
                    try:
                        d = int(value)
                    except ValueError:
                        d = -1
                    if not 0 <= d <= 255:
                        raise GenError(f"{source}:{line_no}: bad `# min_hamming` value {value!r}")
            continue
        if grid is None:
            sides = [n for n in range(3, MAX_GRID + 1) if n * n == len(line)]
            if not sides:
                raise GenError(f"{source}:{line_no}: line length {len(line)} is not a square of 3..16")
            grid = sides[0]
        if len(line) != grid * grid:
            raise GenError(f"{source}:{line_no}: line length {len(line)} != {grid}*{grid}")
        if set(line) - {"0", "1"}:
            raise GenError(f"{source}:{line_no}: character other than 0 and 1")
        rows.append(line)
    if grid is None or not rows:
        raise GenError(f"{source}: no code lines")
    if len(rows) > 0xFFFF:
        raise GenError(f"{source}: more than 65535 codes")
    grids = np.array([[c == "1" for c in r] for r in rows], dtype=bool).reshape(len(rows), grid, grid)
    return Parsed(name, grid, headers, grids, source)


def ring_map(n: int) -> np.ndarray:
    r = np.arange(n)
    rr, cc = np.meshgrid(r, r, indexing="ij")
    return np.minimum(np.minimum(rr, cc), np.minimum(n - 1 - rr, n - 1 - cc))


@dataclass
class Layout:
    grid: int
    quiet_rings: int
    border_ring: int
    data_mask: np.ndarray  # (n, n) bool
    data_cells: list[tuple[int, int]]  # row-major order

    @property
    def bits(self) -> int:
        return len(self.data_cells)

    @property
    def reversed(self) -> bool:
        return self.quiet_rings < self.border_ring


def derive_layout(grids: np.ndarray, source: str) -> Layout:
    count, n, _ = grids.shape
    rings = ring_map(n)
    all_black = [bool((~grids[:, rings == k]).all()) for k in range(n // 2 + 1)]
    all_white = [bool(grids[:, rings == k].all()) for k in range(n // 2 + 1)]
    border = next((r for r in range(n // 2) if all_black[r] and n - 2 * r > 2), None)
    if border is None:
        raise GenError(f"{source}: no ring of cells is black in every code")
    quiet = 0
    while quiet < border and all_white[quiet]:
        quiet += 1
    reversed_ = quiet < border
    if reversed_ and not (border + 1 < len(all_white) and all_white[border + 1]):
        raise GenError(f"{source}: data outside the black border but no white ring inside it")
    # CellRole as in Family::role.
    data = np.ones((n, n), dtype=bool)
    data[rings == border] = False
    data[rings < quiet] = False
    if reversed_:
        data[rings == border + 1] = False
    cells = [(r, c) for r in range(n) for c in range(n) if data[r, c]]
    if not 0 < len(cells) <= MAX_BITS:
        raise GenError(f"{source}: {len(cells)} data cells (need 1..=64)")
    return Layout(n, quiet, border, data, cells)


def pack(grids: np.ndarray, layout: Layout) -> np.ndarray:
    """Data cells row-major, first cell = most significant of the `bits` bits."""
    bits = grids[:, layout.data_mask].astype(np.uint64)  # row-major boolean indexing
    weights = np.array([1 << (layout.bits - 1 - i) for i in range(layout.bits)], dtype=np.uint64)
    return (bits * weights).sum(axis=1, dtype=np.uint64)


def unpack(codes: np.ndarray, bits: int) -> np.ndarray:
    shifts = np.array([bits - 1 - i for i in range(bits)], dtype=np.uint64)
    return ((codes[:, None] >> shifts[None, :]) & np.uint64(1)).astype(bool)


def rotate_grid_index(n: int, row: int, col: int, rotation: int) -> tuple[int, int]:
    last = n - 1
    k = rotation & 3
    if k == 0:
        return row, col
    if k == 1:
        return col, last - row
    if k == 2:
        return last - row, last - col
    return last - col, row


def rotate_codes(codes: np.ndarray, layout: Layout, rotation: int) -> np.ndarray:
    """Family::rotate_code for every code: bit i of the result (canonical data cell (r, c))
    is the cell found at rotate_grid_index(r, c, rotation) in the code's grid."""
    index = {cell: i for i, cell in enumerate(layout.data_cells)}
    perm = []
    for r, c in layout.data_cells:
        src = rotate_grid_index(layout.grid, r, c, rotation)
        if src not in index:  # cannot happen: every role depends on the ring only
            raise GenError("layout is not rotation symmetric")
        perm.append(index[src])
    bits = unpack(codes, layout.bits)[:, perm]
    weights = np.array([1 << (layout.bits - 1 - i) for i in range(layout.bits)], dtype=np.uint64)
    return (bits.astype(np.uint64) * weights).sum(axis=1, dtype=np.uint64)


def popcount(x: np.ndarray) -> np.ndarray:
    if hasattr(np, "bitwise_count"):
        return np.bitwise_count(x)
    out = np.zeros(x.shape, dtype=np.uint8)
    for shift in range(0, 64, 8):
        byte = ((x >> np.uint64(shift)) & np.uint64(0xFF)).astype(np.uint8)
        out += np.unpackbits(byte[..., None], axis=-1).sum(axis=-1, dtype=np.uint8)
    return out


@dataclass
class Distance:
    value: int
    witness: str


def min_hamming(codes: np.ndarray, layout: Layout, skip_self: list[int] | None = None) -> Distance:
    """min_hamming_of: all pairs in all rotations, and each code vs its own rotations (but
    not the ids in `skip_self`)."""
    bits = layout.bits
    best, witness = bits, "bit count (no closer pair)"
    rotated = [rotate_codes(codes, layout, k) for k in range(4)]
    for k in (1, 2, 3):
        d = popcount(codes ^ rotated[k]).astype(np.int16)
        if skip_self:
            d[skip_self] = 999
        i = int(np.argmin(d))
        if int(d[i]) < best:
            best, witness = int(d[i]), f"id {i} vs itself turned {k} quarter(s)"
    n = len(codes)
    block = 256
    for k in range(4):
        for start in range(0, n, block):
            a = rotated[k][start : start + block]
            d = popcount(a[:, None] ^ codes[None, :]).astype(np.int16)
            rows = np.arange(start, start + len(a))
            d[np.arange(n)[None, :] <= rows[:, None]] = 999  # only pairs i < j
            flat = int(np.argmin(d))
            i, j = divmod(flat, n)
            if int(d[i, j]) < best:
                best = int(d[i, j])
                turned = f" turned {k} quarter(s)" if k else ""
                witness = f"id {start + i}{turned} vs id {j}"
    return Distance(best, witness)


def max_correction_for(bits: int, codes: int, min_hamming_: int) -> int:
    """Same floating-point operations, in the same order, as core's max_correction_for."""
    unique = max(min_hamming_ - 1, 0) // 2
    space = 1.0
    for _ in range(bits):
        space *= 2.0
    ball = 0.0
    choose = 1.0
    chosen = 0
    for k in range(unique + 1):
        if k > 0:
            choose = choose * (float(bits) - (float(k) - 1.0)) / float(k)
        ball += choose
        p = 4.0 * float(codes) * ball / space
        if p > MAX_FALSE_ACCEPT:
            break
        chosen = k
    return chosen


# --------------------------------------------------------------------------------------
# Multi-index (core/src/family/index.rs)
# --------------------------------------------------------------------------------------

MAX_CHUNK_BITS = 16  # MAX_CHUNK_BITS in core/src/family/index.rs
# Cortex-M7 instructions, for `choose_chunks`: one bucket look-up of one reading in one chunk
# and one code verified against a reading (xor, software popcount of a u64, compare) are
# estimates; one code of the linear scan (four readings) is measured on bench/m7: ~47,000
# per candidate that is not a marker, over the 837 codes of tag36h11 and aruco_6x6_250.
LOOKUP_INSNS = 12
VERIFY_INSNS = 35
SCAN_INSNS_PER_CODE = 56
# Flash bytes an index may spend to save one instruction per decode. At 4, aruco_6x6_250 gets
# 4 chunks of 9 bits rather than 8+7+7+7+7: 2,058 bytes more, measured 1.2 M instructions
# less on bench/m7's qvga-adv-quads frame (540 bordered quads that are not markers).
BYTES_PER_INSN = 4


def even_chunks(bits: int, count: int) -> list[int]:
    """`bits` split into `count` chunks as even as possible, the wider ones first."""
    base, extra = divmod(bits, count)
    return [base + 1] * extra + [base] * (count - extra)


def index_flash(widths: list[int], codes: int) -> int:
    """Bytes of the index: the u16 bucket offsets and the u16 ids of every chunk."""
    return 2 * (sum((1 << w) + 1 for w in widths) + len(widths) * codes)


def index_insns(widths: list[int], codes: int) -> float:
    """Expected instructions of one indexed look-up of a reading that matches nothing: four
    readings, each looked up in every chunk, verifying the bucket's codes (n / 2^w of them on
    average for a random reading)."""
    return 4 * sum(LOOKUP_INSNS + VERIFY_INSNS * codes / (1 << w) for w in widths)


def choose_chunks(bits: int, codes: int, max_correction: int) -> list[int] | None:
    """The chunk widths of a family's multi-index, or None when it has none.

    Any split into more than `max_correction` chunks finds every code within that many bits
    (pigeonhole). Few wide chunks make small buckets (fast) but large offset tables; many
    narrow chunks the reverse. The choice minimises flash bytes plus BYTES_PER_INSN times the
    expected instructions per look-up, against no index at all (a linear scan, no flash), so a
    family with very few codes keeps the scan."""
    if max_correction == 0:
        return None
    best_cost, best = BYTES_PER_INSN * SCAN_INSNS_PER_CODE * codes, None
    for count in range(max_correction + 1, bits + 1):
        widths = even_chunks(bits, count)
        if widths[0] > MAX_CHUNK_BITS:
            continue
        cost = index_flash(widths, codes) + BYTES_PER_INSN * index_insns(widths, codes)
        if cost < best_cost:
            best_cost, best = cost, widths
    return best


def multi_index(codes: np.ndarray, widths: list[int]) -> tuple[list[int], list[int]]:
    """Bucket offsets and ids of every chunk, chunk 0 on the least significant bits."""
    values = [int(c) for c in codes]
    starts: list[int] = []
    ids: list[int] = []
    shift = 0
    for w in widths:
        chunk = [(v >> shift) & ((1 << w) - 1) for v in values]
        counts = [0] * (1 << w)
        for c in chunk:
            counts[c] += 1
        offsets = [0]
        for c in counts:
            offsets.append(offsets[-1] + c)
        starts += offsets
        ids += sorted(range(len(values)), key=lambda i: (chunk[i], i))
        shift += w
    if shift != sum(widths):
        raise GenError("chunk widths do not add up")
    return starts, ids


def index_summary(fam: "Family") -> str:
    widths = fam.chunk_bits
    if widths is None:
        return "none"
    shape = f"{len(widths)} x {widths[0]}" if len(set(widths)) == 1 else "+".join(map(str, widths))
    return f"{shape} bits, {index_flash(widths, len(fam.codes)):,} B"


# --------------------------------------------------------------------------------------
# Families
# --------------------------------------------------------------------------------------


@dataclass
class Family:
    name: str
    layout: Layout
    codes: np.ndarray  # uint64
    min_hamming: int
    header_min_hamming: int | None
    witness: str
    max_correction: int
    source: str
    notes: list[str] = field(default_factory=list)

    @property
    def ident(self) -> str:
        return static_ident(self.name)

    @property
    def chunk_bits(self) -> list[int] | None:
        return choose_chunks(self.layout.bits, len(self.codes), self.max_correction)

    @property
    def module(self) -> str:
        return self.ident.lower()


def contract_name(file_name: str) -> str:
    """`tagAruco6x6_250` -> `aruco_6x6_250`, `tagArucoMIP_36h12` -> `aruco_mip_36h12`; AprilTag
    names (`tag36h11`, `tagStandard41h12`) stay as they are."""
    m = re.fullmatch(r"tag[Aa]ruco_?(.+)", file_name)
    if m:
        return "aruco_" + m.group(1).lower()
    return file_name


def static_ident(name: str) -> str:
    """`tagStandard41h12` -> `TAG_STANDARD41H12`, `aruco_6x6_250` -> `ARUCO_6X6_250`."""
    s = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name)
    s = re.sub(r"[^A-Za-z0-9_]", "_", s).upper()
    if not s or s[0].isdigit():
        s = "F_" + s
    return s


def self_symmetric_ids(codes: np.ndarray, layout: Layout) -> list[int]:
    same = np.zeros(len(codes), dtype=bool)
    for k in (1, 2, 3):
        same |= codes == rotate_codes(codes, layout, k)
    return np.nonzero(same)[0].tolist()


def duplicate_pairs(codes: np.ndarray, layout: Layout) -> list[tuple[int, int, int]]:
    """(i, j, k) with i < j and code i turned k quarters equal to code j."""
    pos = {int(c): i for i, c in enumerate(codes)}
    if len(pos) != len(codes):
        return [(-1, -1, 0)]
    out = []
    for k in range(4):
        for i, c in enumerate(rotate_codes(codes, layout, k)):
            j = pos.get(int(c))
            if j is not None and j != i:
                out.append((min(i, j), max(i, j), k))
    return out


def build_family(
    name: str, grids: np.ndarray, source: str, headers: dict[str, str], allow_symmetric: bool = False
) -> Family:
    layout = derive_layout(grids, source)
    codes = pack(grids, layout)
    notes = []
    if "data_bits" in headers and int(headers["data_bits"]) != layout.bits:
        raise GenError(f"{source}: `# data_bits {headers['data_bits']}` but the layout has {layout.bits} data cells")
    if "codes" in headers and int(headers["codes"]) != len(codes):
        raise GenError(f"{source}: `# codes {headers['codes']}` but the file has {len(codes)} codes")
    if "border_cells" in headers:
        # Family::quad_cells: the border's outer edge, its inner edge for reversed families.
        edge_ring = layout.border_ring + (1 if layout.reversed else 0)
        border_cells = layout.grid - 2 * edge_ring
        if int(headers["border_cells"]) != border_cells:
            raise GenError(f"{source}: `# border_cells {headers['border_cells']}` but the detected edge spans {border_cells}")
    if "reversed_border" in headers and (headers["reversed_border"] == "true") != layout.reversed:
        raise GenError(f"{source}: `# reversed_border {headers['reversed_border']}` disagrees with the layout")
    dist = min_hamming(codes, layout)
    if dist.value == 0:
        # Two ids that are the same marker are an error (core's `into_family` says
        # DuplicateCode). A code equal to one of its own rotations keeps a unique id but has
        # no defined orientation; only `allow_symmetric` (a dictionary we must interoperate
        # with, e.g. OpenCV's DICT_ARUCO_ORIGINAL) lets that through, loudly, with distance 0.
        symmetric = self_symmetric_ids(codes, layout)
        if not allow_symmetric or dist.witness.find("itself") < 0 or duplicate_pairs(codes, layout):
            raise GenError(f"{source}: two codes are equal or rotations of each other ({dist.witness})")
        rest = min_hamming(codes, layout, skip_self=symmetric)
        msg = (
            f"{name} ({source}): code(s) `{symmetric}` equal their own rotation, so their "
            f"orientation is ambiguous; minimum distance 0 (without that: {rest.value}, "
            f"{rest.witness}), no error correction"
        )
        loud(msg)
        notes.append(msg)
    header_d = int(headers["min_hamming"]) if "min_hamming" in headers else None
    if header_d is not None and header_d != dist.value:
        msg = (
            f"{name} ({source}): header says min_hamming {header_d}, computed {dist.value} "
            f"({dist.witness}); using {dist.value}"
        )
        loud(msg)
        notes.append(msg)
    return Family(
        name=name,
        layout=layout,
        codes=codes,
        min_hamming=dist.value,
        header_min_hamming=header_d,
        witness=dist.witness,
        max_correction=max_correction_for(layout.bits, len(codes), dist.value),
        source=source,
        notes=notes,
    )


def display_path(path: Path) -> str:
    """A path relative to the repository's parent when possible (`shared/data/...`)."""
    path = path.resolve()
    for base, prefix in ((REPO, ""), (REPO.parent, "../")):
        try:
            return prefix + str(path.relative_to(base))
        except ValueError:
            pass
    return str(path)


def load_file(path: Path, name: str | None = None) -> Family:
    parsed = parse_text(path.read_text(), display_path(path))
    file_name = parsed.name or path.stem
    return build_family(name or contract_name(file_name), parsed.grids, parsed.source, parsed.headers)


# --------------------------------------------------------------------------------------
# OpenCV
# --------------------------------------------------------------------------------------


def import_cv2():
    try:
        import cv2  # noqa: PLC0415

        cv2.aruco.getPredefinedDictionary  # noqa: B018
    except (ImportError, AttributeError) as e:
        raise GenError(f"opencv-contrib-python (cv2.aruco) is needed for aruco_original: {e}")
    return cv2


def opencv_grids(cv2, dict_name: str, quiet: int = 1) -> np.ndarray:
    """Cell grids of every marker of an OpenCV dictionary, with `quiet` white rings added."""
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dict_name))
    side = d.markerSize + 2
    out = []
    for i in range(d.bytesList.shape[0]):
        img = cv2.aruco.generateImageMarker(d, i, side, borderBits=1)
        if img.shape != (side, side) or not np.isin(img, (0, 255)).all():
            raise GenError(f"OpenCV {dict_name} id {i}: unexpected image {img.shape}")
        out.append(np.pad(img == 255, quiet, constant_values=True))
    return np.array(out, dtype=bool)


def opencv_family(cv2, name: str, dict_name: str) -> Family:
    grids = opencv_grids(cv2, dict_name)
    source = f"OpenCV {cv2.__version__} cv2.aruco.{dict_name} (opencv-contrib-python)"
    return build_family(name, grids, source, {}, allow_symmetric=True)


def opencv_dict_for(name: str) -> tuple[str, int] | None:
    """The OpenCV dictionary holding a shipped family, and the quarter turns (clockwise as
    seen) between our grid and OpenCV's marker image."""
    m = re.fullmatch(r"aruco_(\d)x\d_(\d+)", name)
    if m:
        return f"DICT_{m.group(1)}X{m.group(1)}_{m.group(2)}", 0
    if name == "aruco_mip_36h12":
        return "DICT_ARUCO_MIP_36H12", 0
    m = re.fullmatch(r"tag(\d\d)h(\d+)", name)
    if m:
        return f"DICT_APRILTAG_{m.group(1)}H{m.group(2)}", 2
    return None


def cross_check(cv2, families: list[tuple[Family, Path]], only: set[str] | None) -> list[str]:
    lines = []
    for fam, path in families:
        entry = opencv_dict_for(fam.name)
        if entry is None or (only is not None and fam.name not in only):
            continue
        dict_name, turns = entry
        if not hasattr(cv2.aruco, dict_name):
            lines.append(f"  {fam.name:<17} OpenCV has no {dict_name}: skipped")
            continue
        ours = parse_text(path.read_text(), str(path)).grids
        theirs = np.rot90(opencv_grids(cv2, dict_name), k=-turns, axes=(1, 2))
        if ours.shape != theirs.shape:
            lines.append(f"  {fam.name:<17} MISMATCH: shape {ours.shape} vs OpenCV {theirs.shape}")
            continue
        bad = np.nonzero((ours != theirs).reshape(len(ours), -1).any(axis=1))[0]
        how = "equal" if turns == 0 else f"equal after {90 * turns} degrees"
        if len(bad) == 0:
            lines.append(f"  {fam.name:<17} {dict_name:<22} {len(ours):>5} codes: {how}, cell for cell")
        else:
            lines.append(f"  {fam.name:<17} {dict_name:<22} MISMATCH in {len(bad)} codes (first ids {bad[:5].tolist()})")
    return lines


# --------------------------------------------------------------------------------------
# Rust output
# --------------------------------------------------------------------------------------


def hex_width(bits: int) -> int:
    return max(1, (bits + 3) // 4)


def rust_table(
    fam: Family, ident: str, crate_path: str, header_doc: list[str], prefix_of: "Family | None" = None
) -> str:
    """One family's table. With `prefix_of`, the family's codes are the first codes of that
    larger family (OpenCV's smaller ArUco dictionaries are prefixes of the 1000-code ones), so
    they are borrowed from its table instead of being stored twice."""
    codes = [int(c) for c in fam.codes]
    order = sorted(range(len(codes)), key=lambda i: codes[i])
    w = hex_width(fam.layout.bits)
    n = len(codes)
    widths = fam.chunk_bits
    out = [f"//! {line}".rstrip() for line in header_doc]
    out += [
        "",
        f"use {crate_path}::family::Family;" if widths is None else f"use {crate_path}::family::{{Family, MultiIndex}};",
        "",
        f"/// `{fam.name}`: {n} code{'' if n == 1 else 's'} of {fam.layout.bits} bits, "
        f"{fam.layout.grid}x{fam.layout.grid} cells, minimum distance {fam.min_hamming}, "
        f"corrects up to {fam.max_correction} bit{'' if fam.max_correction == 1 else 's'}.",
        f"pub static {ident}: Family<'static> = Family {{",
        f'    name: "{fam.name}",',
        f"    grid: {fam.layout.grid},",
        f"    quiet_rings: {fam.layout.quiet_rings},",
        f"    border_ring: {fam.layout.border_ring},",
        f"    bits: {fam.layout.bits},",
        f"    min_hamming: {fam.min_hamming},",
        f"    max_correction: {fam.max_correction},",
        "    codes: CODES,"
        if prefix_of is not None
        else "    codes: &CODES,",
        "    sorted_ids: &SORTED,",
        "    index: None," if widths is None else "    index: Some(&INDEX),",
        "};",
        "",
    ]
    if prefix_of is not None:
        out += [
            f"/// The codes, indexed by id: the first {n} codes of `{prefix_of.name}`.",
            f"const CODES: &[u64] = super::{prefix_of.module}::CODES.split_at({n}).0;",
        ]
    else:
        out += [
            "/// The codes, indexed by id (kept a few per line: rustfmt would put one per line).",
            "#[rustfmt::skip]",
            # Visible to the sibling tables that borrow a prefix (shipped families only).
            f"{'pub(crate) ' if crate_path == 'crate' else ''}static CODES: [u64; {n}] = [",
        ]
        per_line = max(1, min(8, 96 // (w + 4)))
        for start in range(0, n, per_line):
            out.append("    " + " ".join(f"0x{c:0{w}x}," for c in codes[start : start + per_line]))
        out += ["];"]
    out += ["", "/// Ids sorted by code.", f"static SORTED: [u16; {n}] = ["]
    for start in range(0, n, 12):
        out.append("    " + " ".join(f"{i}," for i in order[start : start + 12]))
    out += ["];", ""]
    if widths is not None:
        starts, ids = multi_index(fam.codes, widths)
        chunks = ", ".join(map(str, widths))
        out += [
            f"/// Multi-index for corrected look-ups: {len(widths)} chunks of {chunks} bits (least",
            f"/// significant first), {index_flash(widths, n):,} bytes of tables.",
            "static INDEX: MultiIndex<'static> = MultiIndex {",
            f"    chunk_bits: &[{chunks}],",
            "    starts: &STARTS,",
            "    ids: &IDS,",
            "};",
            "",
            "/// Bucket offsets of each chunk (kept many per line: rustfmt would put one per line).",
            "#[rustfmt::skip]",
            f"static STARTS: [u16; {len(starts)}] = [",
        ]
        for start in range(0, len(starts), 16):
            out.append("    " + " ".join(f"{i}," for i in starts[start : start + 16]))
        out += [
            "];",
            "",
            "/// Ids of each chunk grouped by bucket (kept many per line: rustfmt would put one per line).",
            "#[rustfmt::skip]",
            f"static IDS: [u16; {len(ids)}] = [",
        ]
        for start in range(0, len(ids), 16):
            out.append("    " + " ".join(f"{i}," for i in ids[start : start + 16]))
        out += ["];", ""]
    return "\n".join(out)


def same_layout(a: Layout, b: Layout) -> bool:
    return (a.grid, a.quiet_rings, a.border_ring, a.data_cells) == (b.grid, b.quiet_rings, b.border_ring, b.data_cells)


def prefix_parent(fam: Family, families: list[Family]) -> "Family | None":
    """The largest family with the same layout whose first codes are exactly `fam`'s."""
    best = None
    for other in families:
        if other is fam or len(other.codes) <= len(fam.codes) or not same_layout(other.layout, fam.layout):
            continue
        if [int(c) for c in other.codes[: len(fam.codes)]] == [int(c) for c in fam.codes]:
            if best is None or len(other.codes) > len(best.codes):
                best = other
    return best


def family_doc(fam: Family, command: str) -> list[str]:
    layout = fam.layout
    kind = "reversed (data outside the border)" if layout.reversed else "normal"
    doc = [
        f"The `{fam.name}` marker family: generated by `tools/gen_families.py`, do not edit.",
        "",
        f"Source: `{fam.source}`.",
        f"Regenerate: `{command}`.",
        "",
        f"Layout: {layout.grid}x{layout.grid} cells, {layout.quiet_rings} quiet ring(s), border ring "
        f"{layout.border_ring}, {kind}, {layout.bits} data bits.",
    ]
    d = f"Minimum distance {fam.min_hamming} (closest: {fam.witness})"
    if fam.header_min_hamming is not None and fam.header_min_hamming != fam.min_hamming:
        d += f"; the file's header says {fam.header_min_hamming}"
    doc.append(d + ".")
    return doc


MOD_TESTS = r"""
#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use std::{string::String, vec, vec::Vec};
    use crate::family::{max_correction_for, min_hamming_of};

    /// Code counts of the shipped families (public facts about the dictionaries).
    fn expected_count(name: &str) -> usize {
        match name {
            "tag16h5" => 30,
            "tag25h9" => 35,
            "tag36h10" => 2320,
            "tag36h11" => 587,
            "aruco_mip_36h12" => 250,
            "aruco_original" => 1024,
            "tagStandard41h12" => 2115,
            other => other.rsplit('_').next().unwrap().parse().unwrap(),
        }
    }

    /// Deterministic pseudo-random bit positions (xorshift), `count` distinct ones below `bits`.
    fn error_pattern(seed: u64, bits: u8, count: u32) -> u64 {
        let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        let mut mask = 0u64;
        while mask.count_ones() < count {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            mask |= 1u64 << (state % bits as u64);
        }
        mask
    }

    fn readings(f: &Family<'_>, code: u64) -> [u64; 4] {
        [0u8, 1, 2, 3].map(|k| f.rotate_code(code, k))
    }

    #[test]
    fn every_family_validates() {
        assert_eq!(ALL.len(), CONTRACT.len() + 1);
        for f in ALL {
            assert_eq!(f.validate(), Ok(()), "{}", f.name);
        }
    }

    #[test]
    fn contract_names_in_order() {
        let names: Vec<&str> = names().collect();
        assert_eq!(&names[..CONTRACT.len()], CONTRACT);
        assert_eq!(names[CONTRACT.len()], "tagStandard41h12");
        assert_eq!(DEFAULT.iter().map(|f| f.name).collect::<Vec<_>>(), ["tag36h11", "aruco_6x6_250"]);
    }

    #[test]
    fn code_counts() {
        for f in ALL {
            assert_eq!(f.codes.len(), expected_count(f.name), "{}", f.name);
            assert_eq!(f.sorted_ids.len(), f.codes.len(), "{}", f.name);
        }
    }

    #[test]
    fn correction_bound_follows_the_formula() {
        for f in ALL {
            assert_eq!(f.max_correction, max_correction_for(f.bits, f.codes.len(), f.min_hamming), "{}", f.name);
            let (t, d) = (f.max_correction as u32, f.min_hamming as u32);
            assert!(t == 0 || 2 * t < d, "{}", f.name);
        }
    }

    #[test]
    fn min_hamming_is_the_true_distance() {
        for f in ALL {
            assert_eq!(f.min_hamming, min_hamming_of(f), "{}", f.name);
        }
    }

    #[test]
    fn by_name_round_trip() {
        for f in ALL {
            assert!(core::ptr::eq(by_name(f.name).unwrap(), *f));
            let upper: String = f.name.to_ascii_uppercase();
            let lower: String = f.name.to_ascii_lowercase();
            assert!(core::ptr::eq(by_name(&upper).unwrap(), *f), "{upper}");
            assert!(core::ptr::eq(by_name(&lower).unwrap(), *f), "{lower}");
        }
        assert!(by_name("Tag36H11").is_some());
        assert!(by_name("tag36h12").is_none());
        assert!(by_name("").is_none());
    }

    #[test]
    fn every_code_decodes_in_every_rotation() {
        for f in ALL {
            for (id, &code) in f.codes.iter().enumerate() {
                for turn in 0..4u8 {
                    let seen = readings(f, f.rotate_code(code, turn));
                    let d = f.decode(&seen, f.max_correction).unwrap_or_else(|| panic!("{} id {id} turn {turn}", f.name));
                    assert_eq!((d.id, d.hamming), (id as u16, 0), "{} id {id} turn {turn}", f.name);
                    assert_eq!(seen[d.rotation as usize], code, "{} id {id} turn {turn}", f.name);
                }
            }
        }
    }

    /// With min distance d >= 2t + 1 between any code and any rotation of any code (itself
    /// included), a reading with t <= max_correction flipped bits is within t of the true code
    /// in the true rotation and at least d - t > t from every other (id, rotation): the decode
    /// is that id, unique.
    #[test]
    fn max_correction_flips_decode_to_the_same_id() {
        for f in ALL {
            let t = f.max_correction as u32;
            for (id, &code) in f.codes.iter().enumerate() {
                for turn in 0..4u8 {
                    let bad = code ^ error_pattern((id as u64) << 2 | turn as u64, f.bits, t);
                    let seen = readings(f, f.rotate_code(bad, turn));
                    let d = f.decode(&seen, f.max_correction).unwrap_or_else(|| panic!("{} id {id}", f.name));
                    assert_eq!((d.id, d.hamming as u32), (id as u16, t), "{} id {id} turn {turn}", f.name);
                    assert_eq!(seen[d.rotation as usize], bad, "{} id {id}", f.name);
                }
            }
        }
    }

    /// With e flipped bits, t < e, every (id, rotation) is at least d - e away from the reading.
    /// When d - e > t (i.e. e <= d - t - 1) nothing is within the correction bound: the decode
    /// must fail. When d = 2t + 1 a reading with t + 1 errors can lie within t of another
    /// code, so all that holds there is that a reported decode is genuine (its hamming is the
    /// true distance, at most t).
    #[test]
    fn more_flips_never_decode_wrongly() {
        for f in ALL {
            let t = f.max_correction as u32;
            let d = f.min_hamming as u32;
            let mut counts = vec![t + 1];
            if d > 2 * t + 2 {
                counts.push(d - t - 1);
            }
            for e in counts {
                if e > f.bits as u32 {
                    continue;
                }
                for (id, &code) in f.codes.iter().enumerate() {
                    let bad = code ^ error_pattern(((id as u64) << 8) | e as u64, f.bits, e);
                    let seen = readings(f, bad);
                    let got = f.decode(&seen, f.max_correction);
                    if d > e + t {
                        assert_eq!(got, None, "{} id {id} with {e} errors", f.name);
                    } else if let Some(got) = got {
                        let code = f.codes[got.id as usize];
                        let actual = (code ^ seen[got.rotation as usize]).count_ones();
                        assert_eq!(actual, got.hamming as u32, "{} id {id}", f.name);
                        assert!(actual <= t, "{} id {id}", f.name);
                    }
                }
            }
        }
    }
}
"""


def rust_mod(families: list[Family], command: str, source_dir: str) -> str:
    contract = [f for f in families if f.name in CONTRACT_NAMES]
    lines = [
        "//! Generated code tables of the shipped marker families (`tools/gen_families.py`, do not edit).",
        "//!",
        "//! Each submodule holds one family as static data: its layout (grid, quiet rings,",
        "//! border ring), the codes indexed by id (packed data bits, see [`Family`]), the ids sorted",
        "//! by code for exact look-ups, the true minimum Hamming distance (all rotations, each code",
        "//! against its own rotations too) and the correction bound of",
        "//! [`max_correction_for`](super::max_correction_for).",
        "//!",
        f"//! The codes come from the family files in `{source_dir}` (AprilTag's and OpenCV's",
        "//! dictionaries, same ids as the markers users print); `aruco_original` is OpenCV's",
        "//! `DICT_ARUCO_ORIGINAL`, taken from opencv-contrib-python's `generateImageMarker` with a",
        "//! white quiet ring added. Regenerate everything with",
        "//!",
        "//! ```text",
        f"//! {command}",
        "//! ```",
        "//!",
        "//! | family | grid | bits | codes | min distance | max correction | multi-index |",
        "//! |---|---:|---:|---:|---:|---:|---:|",
    ]
    for f in families:
        lines.append(
            f"//! | `{f.name}` | {f.layout.grid} | {f.layout.bits} | {len(f.codes)} | {f.min_hamming} | {f.max_correction} | {index_summary(f)} |"
        )
    lines += [
        "//!",
        "//! The correction bound is the largest `k` below half the minimum distance for which a random",
        f"//! pattern inside a valid border is accepted with probability at most {MAX_FALSE_ACCEPT:g}",
        "//! ([`MAX_FALSE_ACCEPT`](super::MAX_FALSE_ACCEPT)).",
        "//!",
        "//! Families that correct bits carry a [`MultiIndex`](super::MultiIndex) (chunk widths and",
        "//! flash bytes in the last column) chosen by the generator to balance flash against look-up",
        "//! cost; a family with so few codes that scanning them is as fast has none.",
    ]
    notes = [n for f in families for n in f.notes]
    if notes:
        lines += ["//!", "//! Notes from the generator:"]
        lines += [f"//! - {n}" for n in notes]
    lines += ["", "use super::Family;", ""]
    for f in families:
        lines.append(f"pub mod {f.module};")
    lines.append("")
    for f in families:
        lines.append(f"pub use {f.module}::{f.ident};")
    lines += [
        "",
        "/// Every shipped family: the contract's names in contract order, then `tagStandard41h12`.",
        "pub static ALL: &[&Family<'static>] = &[",
    ]
    lines += [f"    &{f.ident}," for f in families]
    lines += [
        "];",
        "",
        "/// The families the CLI searches when no `--family` is given.",
        "pub static DEFAULT: &[&Family<'static>] = &[" + ", ".join(f"&{static_ident(n)}" for n in DEFAULT_NAMES) + "];",
        "",
        "/// A shipped family by its contract name (`tag36h11`, `aruco_6x6_250`, ...), ignoring ASCII case.",
        "pub fn by_name(name: &str) -> Option<&'static Family<'static>> {",
        "    ALL.iter().copied().find(|f| f.name.eq_ignore_ascii_case(name))",
        "}",
        "",
        "/// The names of the shipped families, in the order of [`ALL`].",
        "pub fn names() -> impl Iterator<Item = &'static str> {",
        "    ALL.iter().map(|f| f.name)",
        "}",
        "",
        "/// The contract's family names (`docs/interfaces.md`), in contract order.",
        "#[cfg(test)]",
        "const CONTRACT: &[&str] = &[" + ", ".join(f'"{f.name}"' for f in contract) + "];",
    ]
    return "\n".join(lines) + "\n" + MOD_TESTS


def run_rustfmt(paths: list[Path]) -> None:
    exe = shutil.which("rustfmt")
    if exe is None:
        loud("rustfmt not found: generated files are not formatted")
        return
    subprocess.run([exe, "--edition", "2021", *map(str, paths)], check=True)


def formatted(text: str) -> str:
    exe = shutil.which("rustfmt")
    if exe is None:
        return text
    res = subprocess.run([exe, "--edition", "2021", "--emit", "stdout"], input=text, capture_output=True, text=True, check=True)
    return res.stdout


# --------------------------------------------------------------------------------------
# Main
# --------------------------------------------------------------------------------------


def default_families_dir() -> Path:
    env = os.environ.get("TOUCHDOWN_DATA")
    if env:
        return Path(env) / "families"
    return REPO.parent / "shared" / "data" / "families"


def print_table(families: list[Family]) -> None:
    print(f"{'family':<18}{'grid':>5}{'bits':>6}{'codes':>7}{'header d':>10}{'computed d':>12}{'max corr':>10}  multi-index")
    for f in families:
        header = "-" if f.header_min_hamming is None else str(f.header_min_hamming)
        flag = "" if f.header_min_hamming in (None, f.min_hamming) else "  <-- MISMATCH"
        print(f"{f.name:<18}{f.layout.grid:>5}{f.layout.bits:>6}{len(f.codes):>7}{header:>10}{f.min_hamming:>12}{f.max_correction:>10}  {index_summary(f)}{flag}")


def shipped(args) -> int:
    fam_dir = Path(args.families) if args.families else default_families_dir()
    if not fam_dir.is_dir():
        raise GenError(f"family directory not found: {fam_dir} (use --families DIR)")
    files = sorted(fam_dir.glob("*.txt"))
    if not files:
        raise GenError(f"no *.txt family files in {fam_dir}")
    cv2 = import_cv2()
    loaded: dict[str, tuple[Family, Path | None]] = {}
    for path in files:
        fam = load_file(path)
        if fam.name in loaded:
            raise GenError(f"two files define family {fam.name}")
        loaded[fam.name] = (fam, path)
    for name, dict_name in OPENCV_ONLY.items():
        if name not in loaded:
            loaded[name] = (opencv_family(cv2, name, dict_name), None)
    missing = [n for n in CONTRACT_NAMES if n not in loaded]
    if missing:
        raise GenError(f"contract families missing from {fam_dir}: {', '.join(missing)}")
    if "tagStandard41h12" not in loaded:
        raise GenError(f"tagStandard41h12 missing from {fam_dir}")
    extra = sorted(n for n in loaded if n not in CONTRACT_NAMES and n != "tagStandard41h12")
    order = CONTRACT_NAMES + ["tagStandard41h12"] + extra
    families = [loaded[n][0] for n in order]
    idents = [f.ident for f in families]
    if len(set(idents)) != len(idents):
        raise GenError(f"two families map to the same Rust identifier: {idents}")

    print_table(families)
    print("\nOpenCV cross-check (shared grids vs cv2.aruco.generateImageMarker, "
          f"OpenCV {cv2.__version__}):")
    checks = cross_check(cv2, [(loaded[n][0], loaded[n][1]) for n in order if loaded[n][1] is not None], None)
    for line in checks:
        print(line)
    mismatched = [c for c in checks if "MISMATCH" in c]

    out_dir = Path(args.out_dir) if args.out_dir else REPO / "core" / "src" / "family" / "tables"
    command = "python3 tools/gen_families.py" + (f" --families {display_path(fam_dir)}" if args.families else "")
    source_dir = display_path(fam_dir)
    outputs: dict[Path, str] = {}
    for f in families:
        text = rust_table(f, f.ident, "crate", family_doc(f, command), prefix_parent(f, families))
        outputs[out_dir / f"{f.module}.rs"] = text
    outputs[out_dir / "mod.rs"] = rust_mod(families, command, source_dir)

    if args.check:
        stale = []
        for path, text in outputs.items():
            if not path.exists() or path.read_text() != formatted(text):
                stale.append(path)
        for path in stale:
            print(f"stale: {path}")
        print("tables are up to date" if not stale else f"{len(stale)} stale file(s)")
        return 1 if stale or mismatched else 0

    out_dir.mkdir(parents=True, exist_ok=True)
    keep = set(outputs)
    for old in out_dir.glob("*.rs"):
        if old not in keep and old.read_text().find("generated by `tools/gen_families.py`") >= 0:
            old.unlink()
            print(f"removed stale {old}")
    for path, text in outputs.items():
        path.write_text(text)
    run_rustfmt(list(outputs))
    print(f"\nwrote {len(outputs)} files to {display_path(out_dir)}")
    if mismatched:
        loud("OpenCV cross-check found mismatches (see above)")
        return 1
    return 0


def user(args) -> int:
    path = Path(args.user)
    parsed = parse_text(path.read_text(), display_path(path))
    name = args.name or parsed.name or path.stem
    fam = build_family(name, parsed.grids, parsed.source, parsed.headers)
    out = Path(args.out)
    crate_path = args.crate_path
    if crate_path is None:
        core_dir = (REPO / "core").resolve()
        crate_path = "crate" if core_dir in out.resolve().parents else "touchdown_core"
    ident = args.static or "USER_FAMILY"
    if not re.fullmatch(r"[A-Z_][A-Z0-9_]*", ident):
        raise GenError(f"--static {ident!r} is not an upper-case Rust identifier")
    parts = ["python3", "tools/gen_families.py", "--user", display_path(path)]
    if args.name:
        parts += ["--name", args.name]
    if args.static:
        parts += ["--static", args.static]
    parts += ["--out", display_path(out)]
    if args.crate_path:
        parts += ["--crate-path", args.crate_path]
    command = " ".join(parts)
    print_table([fam])
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(rust_table(fam, ident, crate_path, family_doc(fam, command)))
    run_rustfmt([out])
    print(f"wrote {out} (static {ident}, crate path `{crate_path}`)")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--families", metavar="DIR", help="family text files (default: $TOUCHDOWN_DATA/families or ../shared/data/families)")
    p.add_argument("--out-dir", metavar="DIR", help="output directory of the shipped tables")
    p.add_argument("--check", action="store_true", help="only check that the tables on disk are up to date")
    p.add_argument("--user", metavar="FILE", help="generate a table for one user family file")
    p.add_argument("--name", help="family name for --user")
    p.add_argument("--static", metavar="IDENT", help="static identifier for --user (default USER_FAMILY)")
    p.add_argument("--out", metavar="PATH", help="output file for --user")
    p.add_argument("--crate-path", metavar="PATH", help="`crate` or `touchdown_core` (default: from --out)")
    args = p.parse_args(argv)
    try:
        if args.user:
            if not args.out:
                p.error("--user needs --out PATH")
            return user(args)
        if args.name or args.out or args.static or args.crate_path:
            p.error("--name/--static/--out/--crate-path go with --user")
        return shipped(args)
    except GenError as e:
        print(f"gen_families: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
