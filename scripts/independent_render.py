#!/usr/bin/env python3
"""independent_render.py: a third image-formation model for touchdown's far-range check.

What it is
----------
Renders the paper scenario's hovers (by default Z = 5, 10, 20, 30, 40, 50 m, 16 frames each,
with a slow ~2 degree tilt wobble) into a recording directory in the contract's format
(docs/interfaces.md: "Recordings", "CAMERA.toml", "pad.toml"), so that

    touchdown replay DIR --no-plots [--json]

scores our pose on imagery our code was never tuned to.

Independence: this file was written from the file formats in docs/interfaces.md and the
family cell grids of shared/data only; nothing in host/sim (our two renderers) was read or is
imported. It shares no code, constants or noise model with them. The only inputs taken from
our simulator are the camera and pad *files* of one of its recordings (--camera-from), so
that intrinsics, resolution, distortion, marker family, id and size are the paper's.

Image model (all its own)
-------------------------
- Scene: the pad's markers printed on white paper (albedo 0.85, ink 0.05) with a white margin
  of --margin-cells cells beyond each marker's black border (default 2; 1 = just the family
  grid's own quiet ring), lying on cluttered ground: value noise in metres at several scales
  (1 cm .. 4 m), patches and speckle, albedo about 0.2-0.4, a new ground per hover. Optional
  soft shadow bands (--shadows) are part of the illumination of the ground plane.
- Projection: for every sub-pixel sample, its ray (through the lens model: Brown-Conrady
  undistortion by fixed-point iteration when camera.toml has distortion) is intersected with
  the pad plane z = 0. The marker and paper are evaluated exactly at that point (cell lookup
  in float64), the ground from a texture rasterised per hover in metres (bilinear).
- Pixel area: stratified jittered supersampling, --supersample per axis over the whole frame
  (default 4) and --roi-supersample (default 16) over a box around each marker's paper; the
  PSF (--psf gaussian:SIGMA | disc:DIAMETER, pixels, default gaussian:0.5, comma list applied
  in turn) is convolved at sample resolution, then each pixel is the mean of its samples.
- Sensor: vignetting (1 - a r^2, a = --vignetting, r = 1 at the frame's corner), gain 255 per
  unit radiance, Gaussian noise of --noise grey levels at mid grey (half read, half shot
  variance), optional --gamma (out = 255 (lin / 255)^(1/G)), 8-bit rounding and clipping.
- Shutter: global (camera.toml is written without line_time_us); no motion blur (the wobble is
  slow: about 0.1 degree over a 30 ms frame).

Truth (frames.csv): the camera centre in the pad frame and the camera-to-pad quaternion
(scalar first), then the vehicle's FRD-to-NED quaternion; the camera is on the nominal
downward mount (image top toward the nose: camera x = body y, camera y = -body x, camera z =
body z) at the body origin, NED-to-pad maps (n, e, d) to (e, n, -d). Level and heading north,
camera-to-pad is diag(1, -1, -1), quaternion (0, 1, 0, 0), as in our own recordings.
Labels (setpoints.csv) are `z=5`, `z=30`, ... as in our paper recording; hovers are separate
sequences (a 1 s gap in t_us), frames at 30 Hz.

Run
---
    touchdown simulate --scenario paper --out /tmp/paper-ours       # only for its camera/pad
    python3 scripts/independent_render.py --camera-from /tmp/paper-ours --out /tmp/indep-r1
    touchdown replay /tmp/indep-r1 --no-plots        # or --json
Options: --seed N (deterministic: same seed and options give the same bytes), --heights
5,10,20,30,40,50, --frames-per-height 16, --margin-cells 2, --psf gaussian:0.5, --gamma 1,
--shadows, --wobble-deg 2, --yaw-deg 10, --noise 2, --vignetting 0.25, --families-dir
(default ../shared/data/families beside the repository),
--force (replace an --out this script wrote earlier). Bad input: one line on stderr, exit status 2;
a missing prerequisite (the modules below, the families directory): one line, exit status 3.
Needs python3 (3.11+, tomllib), numpy and OpenCV (cv2).
"""

import argparse
import math
import os
import shutil
import sys

try:
    import tomllib
except ImportError:  # pragma: no cover
    tomllib = None

try:
    import numpy as np
except ImportError:  # pragma: no cover
    np = None

try:
    import cv2
except ImportError:  # pragma: no cover
    cv2 = None

PROG = "independent_render.py"
FRAME_DT_US = 33333  # 30 Hz
GAP_US = 1_000_000  # between hovers: separate sequences
PAPER_ALBEDO = 0.85
INK_ALBEDO = 0.05


class UserError(Exception):
    pass


class Missing(UserError):
    """A prerequisite is not installed or not there (exit status 3: callers skip)."""


class Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, no usage block
        raise UserError(message)


# ----------------------------------------------------------------------------- inputs

def read_toml(path):
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise UserError(f"{path}: no such file")
    except tomllib.TOMLDecodeError as e:
        raise UserError(f"{path}: not valid TOML ({e})")
    except OSError as e:
        raise UserError(f"{path}: {e.strerror}")


def read_camera(path):
    c = read_toml(path)
    cam = {}
    for key in ("width", "height", "fx", "fy", "cx", "cy"):
        if key not in c:
            raise UserError(f"{path}: missing key `{key}`")
        try:
            cam[key] = float(c[key])
        except (TypeError, ValueError):
            raise UserError(f"{path}: `{key}` is not a number")
    for key in ("width", "height"):
        if cam[key] != int(cam[key]) or not 16 <= cam[key] <= 8192:
            raise UserError(f"{path}: `{key}` must be a whole number of pixels, 16..8192")
        cam[key] = int(cam[key])
    if cam["fx"] <= 0 or cam["fy"] <= 0:
        raise UserError(f"{path}: fx and fy must be positive")
    dist = c.get("distortion", [0.0] * 5)
    if not isinstance(dist, list) or len(dist) != 5:
        raise UserError(f"{path}: `distortion` must be a list of 5 numbers [k1, k2, p1, p2, k3]")
    try:
        cam["distortion"] = [float(d) for d in dist]
    except (TypeError, ValueError):
        raise UserError(f"{path}: `distortion` must be a list of 5 numbers")
    return cam


def read_pad(path):
    p = read_toml(path)
    markers = p.get("marker")
    if not isinstance(markers, list) or not markers:
        raise UserError(f"{path}: no [[marker]] table")
    out = []
    for i, m in enumerate(markers):
        for key in ("family", "id", "size"):
            if key not in m:
                raise UserError(f"{path}: marker {i + 1}: missing key `{key}`")
        try:
            mk = {
                "family": str(m["family"]),
                "id": int(m["id"]),
                "size": float(m["size"]),
                "x": float(m.get("x", 0.0)),
                "y": float(m.get("y", 0.0)),
                "yaw_deg": float(m.get("yaw_deg", 0.0)),
            }
        except (TypeError, ValueError):
            raise UserError(f"{path}: marker {i + 1}: a key has the wrong type")
        if mk["size"] <= 0:
            raise UserError(f"{path}: marker {i + 1}: size must be positive")
        out.append(mk)
    return out


def _family_key(name):
    n = name.lower()
    if n.startswith("tag"):
        n = n[3:]
    return n.replace("_", "").replace("-", "")


def read_family(families_dir, name, marker_id):
    """The family's full cell grid (quiet ring included) for one id: (grid 0/1 uint8, border_cells)."""
    if not os.path.isdir(families_dir):
        raise Missing(f"families directory {families_dir} not found (give --families-dir)")
    want = _family_key(name)
    path = None
    for fn in sorted(os.listdir(families_dir)):
        if fn.endswith(".txt") and _family_key(fn[:-4]) == want:
            path = os.path.join(families_dir, fn)
    if path is None:
        raise UserError(f"family `{name}` has no file in {families_dir}")
    header, codes = {}, []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            if line.startswith("#"):
                parts = line[1:].split(None, 1)
                if len(parts) == 2:
                    header[parts[0]] = parts[1].strip()
                continue
            codes.append(line)
    try:
        cells = int(header["cells"])
        border = int(header["border_cells"])
    except (KeyError, ValueError):
        raise UserError(f"{path}: header lacks `cells` / `border_cells`")
    if header.get("reversed_border", "false") != "false":
        raise UserError(f"{path}: reversed-border families are not supported by this renderer")
    if not 0 <= marker_id < len(codes):
        raise UserError(f"family `{name}` has no id {marker_id} ({len(codes)} codes)")
    code = codes[marker_id]
    if len(code) != cells * cells or set(code) - {"0", "1"}:
        raise UserError(f"{path}: code {marker_id} is not a {cells}x{cells} grid of 0/1")
    grid = np.array([int(ch) for ch in code], dtype=np.uint8).reshape(cells, cells)
    return grid, border


def parse_psf(text):
    items = []
    for item in text.split(","):
        item = item.strip()
        kind, _, val = item.partition(":")
        try:
            v = float(val)
        except ValueError:
            raise UserError(f"--psf: `{item}` is not gaussian:SIGMA or disc:DIAMETER")
        if kind not in ("gaussian", "disc") or not (0 <= v <= 20) or not math.isfinite(v):
            raise UserError(f"--psf: `{item}` is not gaussian:SIGMA or disc:DIAMETER (0..20 px)")
        items.append((kind, v))
    return items


def parse_heights(text):
    try:
        hs = [float(h) for h in text.split(",") if h.strip()]
    except ValueError:
        raise UserError(f"--heights: `{text}` is not a comma list of metres")
    if not hs or any(not (0.5 <= h <= 500) for h in hs):
        raise UserError("--heights: each height must be 0.5..500 m")
    return hs


# ----------------------------------------------------------------------------- geometry

def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


# camera-to-body of the nominal downward mount (image top toward the nose)
MOUNT = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
# NED -> pad: (n, e, d) -> (e, n, -d)
NED_TO_PAD = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def quat_from_matrix(R):
    """Hamilton unit quaternion (w, x, y, z) of an active rotation matrix, w >= 0."""
    m = R
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    if q[0] < 0:
        q = -q
    return q


class Lens:
    def __init__(self, cam):
        self.fx, self.fy, self.cx, self.cy = cam["fx"], cam["fy"], cam["cx"], cam["cy"]
        self.k1, self.k2, self.p1, self.p2, self.k3 = cam["distortion"]
        self.distorted = any(d != 0.0 for d in cam["distortion"])

    def _distort_norm(self, x, y):
        r2 = x * x + y * y
        radial = 1 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        xd = x * radial + 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x)
        yd = y * radial + self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y
        return xd, yd

    def pixel_to_ray(self, u, v):
        """Distorted pixel -> ideal normalised (x, y) (camera ray (x, y, 1))."""
        xd = (u - self.cx) / self.fx
        yd = (v - self.cy) / self.fy
        if not self.distorted:
            return xd, yd
        x, y = xd.copy(), yd.copy()
        for _ in range(30):  # fixed point: x = (xd - tangential(x)) / radial(x)
            r2 = x * x + y * y
            radial = 1 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
            dx = 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x)
            dy = self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y
            x = (xd - dx) / radial
            y = (yd - dy) / radial
        return x, y

    def project(self, Xc):
        """Camera-frame points (N, 3), z > 0 -> distorted pixels (N, 2)."""
        x = Xc[:, 0] / Xc[:, 2]
        y = Xc[:, 1] / Xc[:, 2]
        if self.distorted:
            x, y = self._distort_norm(x, y)
        return np.stack([self.fx * x + self.cx, self.fy * y + self.cy], axis=1)


# ----------------------------------------------------------------------------- scene

class Marker:
    def __init__(self, spec, grid, border_cells, margin_cells):
        self.cx, self.cy = spec["x"], spec["y"]
        yaw = math.radians(spec["yaw_deg"])
        self.c, self.s = math.cos(yaw), math.sin(yaw)
        self.cell = spec["size"] / border_cells
        self.grid = grid
        self.n = grid.shape[0]
        # paper half width, in cells, from the marker centre
        self.half_paper = border_cells / 2.0 + margin_cells

    def local_cells(self, X, Y):
        """Pad-plane points -> marker-frame coordinates in cells (x right, y up)."""
        dx, dy = X - self.cx, Y - self.cy
        mx = self.c * dx + self.s * dy
        my = -self.s * dx + self.c * dy
        return mx / self.cell, my / self.cell

    def paint(self, X, Y, albedo):
        """Overwrite albedo where the paper (and its ink) lies."""
        mx, my = self.local_cells(X, Y)
        on_paper = (np.abs(mx) < self.half_paper) & (np.abs(my) < self.half_paper)
        if not on_paper.any():
            return
        col = np.floor(mx[on_paper] + self.n / 2.0).astype(np.int64)
        row = np.floor(self.n / 2.0 - my[on_paper]).astype(np.int64)
        inside = (col >= 0) & (col < self.n) & (row >= 0) & (row < self.n)
        val = np.full(col.shape, PAPER_ALBEDO)
        white = self.grid[row[inside], col[inside]]
        val[inside] = np.where(white == 1, PAPER_ALBEDO, INK_ALBEDO)
        albedo[on_paper] = val

    def paper_corners(self, pad=0.0):
        h = (self.half_paper + pad) * self.cell
        pts = []
        for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            mx, my = sx * h, sy * h
            pts.append((self.cx + self.c * mx - self.s * my, self.cy + self.s * mx + self.c * my))
        return pts


class Ground:
    """Clutter texture in metres over a rectangle of the pad plane, rasterised once per hover."""

    def __init__(self, rng, x0, x1, y0, y1, texel):
        self.x0, self.y1, self.texel = x0, y1, texel
        w = int(math.ceil((x1 - x0) / texel)) + 2
        h = int(math.ceil((y1 - y0) / texel)) + 2
        if w * h > 40_000_000:
            raise UserError("ground texture too large (lower --supersample or the heights)")
        kind = rng.uniform()  # 0 = grass-like, 1 = concrete-like
        base = rng.uniform(0.22, 0.36)
        tex = np.full((h, w), base, dtype=np.float32)
        # value noise octaves, cell sizes in metres and their amplitudes
        octaves = [(4.0, 0.05), (1.5, 0.04), (0.5, 0.035), (0.15, 0.03 + 0.02 * (1 - kind)),
                   (0.05, 0.025 + 0.03 * (1 - kind)), (0.015, 0.02 + 0.03 * (1 - kind))]
        for size, amp in octaves:
            gw = max(2, int(math.ceil((x1 - x0) / size)) + 3)
            gh = max(2, int(math.ceil((y1 - y0) / size)) + 3)
            if size < 1.5 * texel:
                # finer than the texture: its average over a texel is what is left
                amp = amp * size / (1.5 * texel)
                if amp < 0.003:
                    continue
                tex += (amp * rng.standard_normal((h, w))).astype(np.float32)
                continue
            coarse = rng.standard_normal((gh, gw)).astype(np.float32)
            tex += amp * cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
        # patches: bare soil / moss (grass) or stains and cracks (concrete)
        g = max(2, int((x1 - x0) / 0.8))
        blob = cv2.resize(rng.standard_normal((max(2, int((y1 - y0) / 0.8)), g)).astype(np.float32),
                          (w, h), interpolation=cv2.INTER_CUBIC)
        tex += np.where(blob > 1.2, -0.07, 0.0).astype(np.float32)
        tex += np.where(blob < -1.4, 0.06, 0.0).astype(np.float32)
        if kind > 0.5:
            n_cracks = int(rng.integers(3, 12))
            for _ in range(n_cracks):
                p0 = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
                ang = rng.uniform(0, math.pi)
                ln = rng.uniform(0.1, 0.5) * max(w, h)
                p1 = (int(p0[0] + ln * math.cos(ang)), int(p0[1] + ln * math.sin(ang)))
                thick = max(1, int(round(0.01 / texel)))
                cv2.line(tex, p0, p1, float(base - 0.12), thick, cv2.LINE_AA)
        self.tex = np.clip(tex, 0.10, 0.50)

    def sample(self, X, Y):
        mx = ((X - self.x0) / self.texel - 0.5).astype(np.float32)
        my = ((self.y1 - Y) / self.texel - 0.5).astype(np.float32)
        return cv2.remap(self.tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)


class Shadows:
    """Soft shadow bands (illumination factor) on the pad plane."""

    def __init__(self, rng, z, enabled):
        self.bands = []
        if not enabled:
            return
        for _ in range(int(rng.integers(1, 4))):
            ang = rng.uniform(0, math.pi)
            nx, ny = math.cos(ang), math.sin(ang)
            off = rng.uniform(-0.25, 0.25) * z  # near the marker, at the scene's scale
            width = rng.uniform(0.05, 0.2) * z
            soft = rng.uniform(0.01, 0.05) * z
            depth = rng.uniform(0.35, 0.6)
            self.bands.append((nx, ny, off, width, soft, depth))

    def illumination(self, X, Y):
        light = np.ones_like(X)
        for nx, ny, off, width, soft, depth in self.bands:
            d = np.abs(X * nx + Y * ny - off) - width / 2
            t = np.clip(0.5 - d / soft, 0.0, 1.0)  # 1 inside, 0 outside, linear penumbra
            t = t * t * (3 - 2 * t)
            light *= 1 - depth * t
        return light


# ----------------------------------------------------------------------------- rendering

def intersect_ground(lens, R_cp, C, u, v):
    x, y = lens.pixel_to_ray(u, v)
    dX = R_cp[0, 0] * x + R_cp[0, 1] * y + R_cp[0, 2]
    dY = R_cp[1, 0] * x + R_cp[1, 1] * y + R_cp[1, 2]
    dZ = R_cp[2, 0] * x + R_cp[2, 1] * y + R_cp[2, 2]
    dZ = np.minimum(dZ, -1e-6)  # rays above the horizon: far away
    s = -C[2] / dZ
    return C[0] + s * dX, C[1] + s * dY


def radiance_block(scene, R_cp, C, x0, y0, w, h, S, psf, rng):
    """Mean radiance of pixels [x0, x0+w) x [y0, y0+h), PSF applied at S samples per pixel axis."""
    lens, ground, markers, shadows = scene
    # stratified jittered sample positions; pixel i covers [i - 0.5, i + 0.5]
    ju = rng.uniform(0, 1, (h * S, w * S))
    jv = rng.uniform(0, 1, (h * S, w * S))
    cols = np.arange(w * S, dtype=np.float64)[None, :]
    rows = np.arange(h * S, dtype=np.float64)[:, None]
    u = x0 - 0.5 + (cols + ju) / S
    v = y0 - 0.5 + (rows + jv) / S
    X, Y = intersect_ground(lens, R_cp, C, u, v)
    albedo = ground.sample(X, Y).astype(np.float64)
    for m in markers:
        m.paint(X, Y, albedo)
    rad = (albedo * shadows.illumination(X, Y)).astype(np.float32)
    for kind, val in psf:
        if val <= 0:
            continue
        if kind == "gaussian":
            rad = cv2.GaussianBlur(rad, (0, 0), sigmaX=val * S, sigmaY=val * S,
                                   borderType=cv2.BORDER_REFLECT_101)
        else:
            rad = cv2.filter2D(rad, -1, disc_kernel(val * S / 2.0), borderType=cv2.BORDER_REFLECT_101)
    return rad.reshape(h, S, w, S).mean(axis=(1, 3), dtype=np.float64)


def disc_kernel(radius):
    r = int(math.ceil(radius))
    k = np.zeros((2 * r + 1, 2 * r + 1))
    sub = 8
    o = (np.arange(sub) + 0.5) / sub - 0.5
    for dy in o:
        for dx in o:
            yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
            k += ((xx + dx) ** 2 + (yy + dy) ** 2 <= radius * radius)
    k /= k.sum()
    return k.astype(np.float32)


def psf_reach(psf):
    """Pixels a PSF spreads light: the margin a block needs beyond the pixels it keeps."""
    reach = 0.0
    for kind, val in psf:
        reach += 4 * val if kind == "gaussian" else val / 2 + 1
    return int(math.ceil(reach)) + 2


def render_frame(scene, cam, R_cp, C, args, psf, rng):
    lens, ground, markers, shadows = scene
    W, H = cam["width"], cam["height"]
    img = radiance_block(scene, R_cp, C, 0, 0, W, H, args.supersample, psf, rng)
    # finer sampling over each marker's paper (the edges the pose is measured from)
    reach = psf_reach(psf)
    for m in markers:
        pts = np.array([[px, py, 0.0] for px, py in m.paper_corners(pad=0.5)])
        Xc = (pts - C) @ R_cp  # pad -> camera: R_cp^T (p - C)
        if np.any(Xc[:, 2] <= 0.1):
            continue
        uv = lens.project(Xc)
        u0 = int(math.floor(uv[:, 0].min())) - 2
        u1 = int(math.ceil(uv[:, 0].max())) + 3
        v0 = int(math.floor(uv[:, 1].min())) - 2
        v1 = int(math.ceil(uv[:, 1].max())) + 3
        ku0, ku1 = max(u0, 0), min(u1, W)  # pixels kept
        kv0, kv1 = max(v0, 0), min(v1, H)
        if ku1 <= ku0 or kv1 <= kv0:
            continue
        r0, r1 = max(ku0 - reach, 0), min(ku1 + reach, W)  # rendered with the PSF's reach
        s0, s1 = max(kv0 - reach, 0), min(kv1 + reach, H)
        if (r1 - r0) * (s1 - s0) * args.roi_supersample ** 2 > 60_000_000:
            continue  # too close for the fine pass; the whole-frame sampling stands
        block = radiance_block(scene, R_cp, C, r0, s0, r1 - r0, s1 - s0, args.roi_supersample, psf, rng)
        img[kv0:kv1, ku0:ku1] = block[kv0 - s0:kv1 - s0, ku0 - r0:ku1 - r0]
    # vignetting
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    rc = math.hypot(max(cam["cx"], W - 1 - cam["cx"]), max(cam["cy"], H - 1 - cam["cy"]))
    r2 = ((xx - cam["cx"]) ** 2 + (yy - cam["cy"]) ** 2) / (rc * rc)
    lin = 255.0 * img * (1 - args.vignetting * r2)
    # sensor noise: half read, half shot variance at mid grey
    var = args.noise ** 2 * (0.5 + 0.5 * np.maximum(lin, 0) / 128.0)
    lin = lin + rng.standard_normal(lin.shape) * np.sqrt(var)
    lin = np.clip(lin, 0, 255)
    if args.gamma != 1.0:
        lin = 255.0 * (lin / 255.0) ** (1.0 / args.gamma)
    return np.clip(np.rint(lin), 0, 255).astype(np.uint8)


def hover_poses(rng, z, n, args):
    """Per frame: (t offset s, camera position, camera-to-pad R, vehicle FRD-to-NED R)."""
    yaw0 = math.radians(rng.uniform(-args.yaw_deg, args.yaw_deg))
    xy0 = rng.uniform(-0.3, 0.3, 2)
    amp = math.radians(args.wobble_deg)
    f_r, f_p = rng.uniform(0.15, 0.4, 2)  # Hz: slow
    ph_r, ph_p = rng.uniform(0, 2 * math.pi, 2)
    f_z, ph_z = rng.uniform(0.1, 0.3), rng.uniform(0, 2 * math.pi)
    out = []
    for k in range(n):
        t = k * FRAME_DT_US * 1e-6
        roll = amp * math.sin(2 * math.pi * f_r * t + ph_r)
        pitch = amp * math.sin(2 * math.pi * f_p * t + ph_p)
        yaw = yaw0 + math.radians(0.5) * math.sin(2 * math.pi * 0.2 * t)
        R_bn = rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)  # FRD -> NED (ZYX)
        R_cp = NED_TO_PAD @ R_bn @ MOUNT
        # slow drift: a few cm; height bob about 1 cm per 10 m
        pos = np.array([xy0[0] + 0.05 * math.sin(0.7 * t + ph_r),
                        xy0[1] + 0.05 * math.cos(0.6 * t + ph_p),
                        z + 0.001 * z * math.sin(2 * math.pi * f_z * t + ph_z)])
        out.append((t, pos, R_cp, R_bn))
    return out


def ground_extent(lens, cam, poses):
    xs, ys = [], []
    W, H = cam["width"], cam["height"]
    u = np.array([-1.0, W, W, -1.0, W / 2, -1.0, W, W / 2])
    v = np.array([-1.0, -1.0, H, H, -1.0, H / 2, H / 2, H])
    for _, C, R_cp, _ in poses:
        X, Y = intersect_ground(lens, R_cp, C, u, v)
        xs += list(X)
        ys += list(Y)
    pad = 0.05 * poses[0][1][2] + 0.5
    return min(xs) - pad, max(xs) + pad, min(ys) - pad, max(ys) + pad


# ----------------------------------------------------------------------------- main

def main(argv):
    if tomllib is None or np is None or cv2 is None:
        raise Missing("needs python 3.11+ (tomllib), numpy and OpenCV (cv2)")
    here = os.path.dirname(os.path.abspath(__file__))
    default_fam = os.path.normpath(os.path.join(here, "..", "..", "shared", "data", "families"))
    ap = Parser(prog=PROG, description=__doc__.split("\n\n")[0],
                formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="recording directory to write")
    ap.add_argument("--camera-from", required=True,
                    help="a recording of ours: its camera.toml and pad.toml are used")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--heights", default="5,10,20,30,40,50", help="hover heights, metres")
    ap.add_argument("--frames-per-height", type=int, default=16)
    ap.add_argument("--margin-cells", type=float, default=2.0,
                    help="white paper beyond the black border, cells (default 2)")
    ap.add_argument("--psf", default="gaussian:0.5", help="gaussian:SIGMA|disc:DIAMETER[,...], px")
    ap.add_argument("--gamma", type=float, default=1.0)
    ap.add_argument("--shadows", action="store_true", help="soft shadow bands across the scene")
    ap.add_argument("--wobble-deg", type=float, default=2.0, help="tilt wobble amplitude")
    ap.add_argument("--yaw-deg", type=float, default=10.0, help="heading drawn in +-this per hover")
    ap.add_argument("--noise", type=float, default=2.0, help="grey levels RMS at mid grey")
    ap.add_argument("--vignetting", type=float, default=0.25, help="fall-off at the corners")
    ap.add_argument("--supersample", type=int, default=4, help="samples per pixel axis, whole frame")
    ap.add_argument("--roi-supersample", type=int, default=16,
                    help="samples per pixel axis around each marker")
    ap.add_argument("--families-dir", default=default_fam)
    ap.add_argument("--force", action="store_true", help="replace an --out this script wrote earlier")
    args = ap.parse_args(argv)

    if args.frames_per_height < 1 or args.frames_per_height > 1000:
        raise UserError("--frames-per-height must be 1..1000")
    if args.margin_cells < 0 or args.margin_cells > 50 or not math.isfinite(args.margin_cells):
        raise UserError("--margin-cells must be 0..50")
    if not (0 < args.gamma <= 5) or not math.isfinite(args.gamma):
        raise UserError("--gamma must be over 0, at most 5")
    if not (0 <= args.noise <= 50):
        raise UserError("--noise must be 0..50 grey levels")
    if not (0 <= args.vignetting < 1):
        raise UserError("--vignetting must be 0..1 (exclusive)")
    if not (0 <= args.wobble_deg <= 30) or not (0 <= args.yaw_deg <= 180):
        raise UserError("--wobble-deg must be 0..30 and --yaw-deg 0..180")
    if not (1 <= args.supersample <= 16) or not (1 <= args.roi_supersample <= 32):
        raise UserError("--supersample must be 1..16 and --roi-supersample 1..32")
    if args.seed < 0:
        raise UserError("--seed must not be negative")
    psf = parse_psf(args.psf)
    heights = parse_heights(args.heights)

    src = args.camera_from
    if not os.path.isdir(src):
        raise UserError(f"--camera-from {src}: not a directory")
    cam = read_camera(os.path.join(src, "camera.toml"))
    pad = read_pad(os.path.join(src, "pad.toml"))
    with open(os.path.join(src, "pad.toml")) as f:
        pad_text = f.read()
    lens = Lens(cam)
    markers = []
    for spec in pad:
        grid, border = read_family(args.families_dir, spec["family"], spec["id"])
        markers.append(Marker(spec, grid, border, args.margin_cells))

    out = args.out
    if os.path.exists(out):
        if not os.path.isdir(out):
            raise UserError(f"--out {out}: exists and is not a directory")
        if os.listdir(out):
            if not args.force:
                raise UserError(f"--out {out}: not empty (give --force to replace it)")
            if not os.path.isfile(os.path.join(out, "render.toml")):
                raise UserError(f"--out {out}: not empty and not written by {PROG}; "
                                "--force replaces only its own recordings")
            shutil.rmtree(out)
    try:
        os.makedirs(os.path.join(out, "frames"), exist_ok=True)
    except OSError as e:
        raise UserError(f"--out {out}: {e.strerror}")

    with open(os.path.join(out, "camera.toml"), "w") as f:
        f.write("# independent_render.py: the camera of %s, global shutter\n" % os.path.abspath(src))
        for key in ("width", "height"):
            f.write(f"{key} = {cam[key]}\n")
        for key in ("fx", "fy", "cx", "cy"):
            f.write(f"{key} = {cam[key]!r}\n")
        if lens.distorted:
            f.write("distortion = [%s]\n" % ", ".join(repr(d) for d in cam["distortion"]))
    with open(os.path.join(out, "pad.toml"), "w") as f:
        f.write(pad_text)
    with open(os.path.join(out, "render.toml"), "w") as f:
        f.write("# How this recording was rendered (scripts/independent_render.py); informational.\n")
        for k in ("seed", "heights", "frames_per_height", "margin_cells", "psf", "gamma", "shadows",
                  "wobble_deg", "yaw_deg", "noise", "vignetting", "supersample", "roi_supersample"):
            val = getattr(args, k)
            f.write(f"{k} = {str(val).lower() if isinstance(val, bool) else repr(val)}\n"
                    .replace("'", '"'))

    ss = np.random.SeedSequence(args.seed)
    hover_seeds = ss.spawn(len(heights))
    rows, labels = [], []
    index, t0 = 0, 0
    for z, hseed in zip(heights, hover_seeds):
        pose_seed, ground_seed, frame_seed = hseed.spawn(3)
        poses = hover_poses(np.random.default_rng(pose_seed), z, args.frames_per_height, args)
        grng = np.random.default_rng(ground_seed)
        x0, x1, y0, y1 = ground_extent(lens, cam, poses)
        texel = z / max(cam["fx"], cam["fy"]) / max(args.supersample, 3)
        ground = Ground(grng, x0, x1, y0, y1, texel)
        shadows = Shadows(grng, z, args.shadows)
        scene = (lens, ground, markers, shadows)
        frng = np.random.default_rng(frame_seed)
        label = "z=%s" % (("%g" % z))
        for t, C, R_cp, R_bn in poses:
            img = render_frame(scene, cam, R_cp, C, args, psf, frng)
            path = os.path.join(out, "frames", "%06d.pgm" % index)
            h, w = img.shape
            with open(path, "wb") as f:
                f.write(b"P5\n%d %d\n255\n" % (w, h))
                f.write(img.tobytes())
            qc = quat_from_matrix(R_cp)
            qv = quat_from_matrix(R_bn)
            t_us = t0 + int(round(t * 1e6))
            rows.append([index, t_us] + [repr(float(a)) for a in C] + [repr(float(a)) for a in qc]
                        + [repr(float(a)) for a in qv])
            labels.append((index, label))
            index += 1
            last_t = t_us
        t0 = last_t + GAP_US
        print(f"{PROG}: z = {z:g} m: {args.frames_per_height} frames", file=sys.stderr)

    with open(os.path.join(out, "frames.csv"), "w") as f:
        f.write("index,t_us,cam_x,cam_y,cam_z,cam_qw,cam_qx,cam_qy,cam_qz,"
                "veh_qw,veh_qx,veh_qy,veh_qz\n")
        for r in rows:
            f.write(",".join(str(a) for a in r) + "\n")
    with open(os.path.join(out, "setpoints.csv"), "w") as f:
        f.write("index,label\n")
        for i, lab in labels:
            f.write(f"{i},{lab}\n")
    print(f"{PROG}: wrote {index} frames to {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except Missing as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        sys.exit(3)
    except UserError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)
