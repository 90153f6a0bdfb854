#!/usr/bin/env python3
"""lens_opencv_check.py: a cross-check of `touchdown calibrate-lens` against OpenCV.

Why: the Rust tests (host/cli/tests/calibrate_lens.rs) render their views with the project's
own two image models and check the fit against the truth. This script asks a third party
twice over, outside CI:

1. images: OpenCV draws the views. The board (the tests' 8 x 6 grid of tag36h11 markers,
   0.08 m at 0.11 m) is drawn with cv2.aruco's AprilTag 36h11 dictionary (turned 180 degrees:
   OpenCV draws that family upside down relative to touchdown's canonical image), seen from
   20 seeded poses (tilts 5-45 degrees, the board running off the frame's sides and
   corners) through a Brown-Conrady lens by cv2.remap: every pixel of a 2x grid is undistorted
   with cv2.undistortPoints, carried to the board by the view's plane homography and sampled,
   then averaged 2 x 2 (cv2.resize INTER_AREA), blurred (Gaussian, sigma 0.6 px) and given
   noise (2 grey levels).
2. fit: cv2.calibrateCamera (k3 fixed, as calibrate-lens does by default) on the very corner
   correspondences `touchdown detect --json` finds in those images, matched to the board by
   id, next to `touchdown calibrate-lens --json` on the same images.

Usage: python3 scripts/lens_opencv_check.py --hfov 120 --k1 -0.35 [--k2 K2] [--out DIR]
[--seed N] [--touchdown PATH] [--recording DIR]
(needs `pip install opencv-contrib-python-headless==4.14.0.94` and a built touchdown, default
target/debug/touchdown). With --recording DIR it skips step 1 and runs step 2 on a recording's
frames (a Rust test's, say), against its pad.toml. Prints one table row per method.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tomllib

import cv2
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WIDTH, HEIGHT = 640, 480
COLUMNS, ROWS, EDGE, PITCH = 8, 6, 0.08, 0.11
# Board texture resolution, pixels per metre (a marker cell is 20 texture pixels).
TEXTURE_PPM = 2000.0


def board_markers():
    """(id, x, y) of the grid's markers, ids row by row from the top left."""
    out = []
    for k in range(ROWS * COLUMNS):
        row, col = divmod(k, COLUMNS)
        out.append((k, (col - 0.5 * (COLUMNS - 1)) * PITCH, (0.5 * (ROWS - 1) - row) * PITCH))
    return out


def pad_toml():
    lines = ['name = "lens-board"', ""]
    for k, x, y in board_markers():
        lines += ["[[marker]]", 'family = "tag36h11"', f"id = {k}", f"size = {EDGE}",
                  f"x = {x!r}", f"y = {y!r}", ""]
    return "\n".join(lines)


def lens(hfov, k1, k2):
    """fx = fy, cx, cy, dist for a horizontal field `hfov` of the distorted image."""
    x = math.tan(math.radians(0.5 * hfov))
    r2 = x * x
    xd = x * (1 + r2 * (k1 + r2 * k2))
    f = 0.5 * WIDTH / xd
    return f, 0.5 * (WIDTH - 1) + 4.0, 0.5 * (HEIGHT - 1) - 3.0, np.array([k1, k2, 0, 0, 0], float)


def board_texture():
    """The board as a grey texture (1 = white paper) and the pad point of its (0, 0) pixel."""
    half_w = 0.5 * COLUMNS * PITCH
    half_h = 0.5 * ROWS * PITCH
    w, h = int(2 * half_w * TEXTURE_PPM), int(2 * half_h * TEXTURE_PPM)
    tex = np.full((h, w), 0.85, np.float32)
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    side = int(round(EDGE * TEXTURE_PPM))
    for k, x, y in board_markers():
        marker = cv2.aruco.generateImageMarker(dictionary, k, side, borderBits=1)
        marker = np.rot90(marker, 2).astype(np.float32) / 255.0 * 0.8 + 0.05
        u0 = int(round((x + half_w) * TEXTURE_PPM - 0.5 * side))
        v0 = int(round((half_h - y) * TEXTURE_PPM - 0.5 * side))
        tex[v0:v0 + side, u0:u0 + side] = marker
    return tex, (-half_w, half_h)


def pose(k, f, rng):
    """rvec, tvec (pad to camera) of view k: tilt 5-45 degrees, aim off the board's centre."""
    tilt = math.radians(5 + 40 * (k % 5) / 4) * rng.uniform(0.9, 1.0)
    azimuth = math.radians(k * 137.5 + rng.uniform(0, 20))
    roll = math.radians(rng.uniform(-30, 30))
    reach = 0.1 if k % 4 == 0 else 0.5
    angle = math.radians(k * 77.0)
    aim = np.array([reach * 0.5 * COLUMNS * PITCH * math.cos(angle),
                    reach * 0.5 * ROWS * PITCH * math.sin(angle), 0.0])
    distance = f * COLUMNS * PITCH / WIDTH * rng.uniform(0.85, 1.15)
    centre = aim + distance * np.array([math.sin(tilt) * math.cos(azimuth),
                                        math.sin(tilt) * math.sin(azimuth), math.cos(tilt)])
    z = (aim - centre) / np.linalg.norm(aim - centre)
    x0 = np.array([1.0, 0, 0]) - z * z[0]
    x0 /= np.linalg.norm(x0)
    y0 = np.cross(z, x0)
    x = math.cos(roll) * x0 + math.sin(roll) * y0
    y = np.cross(z, x)
    r_cam_to_pad = np.column_stack([x, y, z])
    r = r_cam_to_pad.T
    t = -r @ centre
    return r, t


def distort(xy, dist):
    k1, k2, p1, p2, k3 = dist
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return np.stack([x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                     y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y], 1)


def polish(rays, pixels, f, cx, cy, dist, steps=8):
    target = np.stack([(pixels[:, 0] - cx) / f, (pixels[:, 1] - cy) / f], 1)
    h = 1e-7
    for _ in range(steps):
        d0 = distort(rays, dist) - target
        jx = (distort(rays + [h, 0], dist) - distort(rays - [h, 0], dist)) / (2 * h)
        jy = (distort(rays + [0, h], dist) - distort(rays - [0, h], dist)) / (2 * h)
        det = jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1]
        rays = rays - np.stack([(jy[:, 1] * d0[:, 0] - jy[:, 0] * d0[:, 1]) / det,
                                (-jx[:, 1] * d0[:, 0] + jx[:, 0] * d0[:, 1]) / det], 1)
    return rays


def render(out, hfov, k1, k2, seed):
    f, cx, cy, dist = lens(hfov, k1, k2)
    camera = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1]])
    tex, (x0, y0) = board_texture()
    rng = np.random.default_rng(seed)
    # Rays of the 2x grid's pixel centres, in the camera's own pixel coordinates.
    us, vs = np.meshgrid((np.arange(2 * WIDTH) + 0.5) / 2 - 0.5, (np.arange(2 * HEIGHT) + 0.5) / 2 - 0.5)
    pts = np.stack([us.ravel(), vs.ravel()], 1).reshape(-1, 1, 2).astype(np.float64)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rays = cv2.undistortPointsIter(pts, camera, dist, np.eye(3), np.eye(3), criteria).reshape(-1, 2)
    # OpenCV's fixed-point inversion is slow to converge at a strong lens's edge: polish by
    # Newton on the model (finite-difference Jacobian), checked against cv2.projectPoints.
    rays = polish(rays, pts.reshape(-1, 2), f, cx, cy, dist)
    back, _ = cv2.projectPoints(np.column_stack([rays, np.ones(len(rays))]), np.zeros(3), np.zeros(3), camera, dist)
    worst = np.abs(back.reshape(-1, 2) - pts.reshape(-1, 2)).max()
    if worst > 1e-3:
        sys.exit(f"the lens does not invert over the frame (worst {worst:.3g} px)")
    paths = []
    for k in range(20):
        r, t = pose(k, f, rng)
        h = np.column_stack([r[:, 0], r[:, 1], t])  # pad (x, y, 1) -> normalised ray
        g = np.linalg.inv(h) @ np.vstack([rays.T, np.ones(len(rays))])
        px = (g[0] / g[2] - x0) * TEXTURE_PPM - 0.5
        py = (y0 - g[1] / g[2]) * TEXTURE_PPM - 0.5
        behind = g[2] <= 0  # g = (x, y, 1) / depth: the plane behind the camera
        px[behind] = -1e6
        big = cv2.remap(tex, px.reshape(2 * HEIGHT, 2 * WIDTH).astype(np.float32),
                        py.reshape(2 * HEIGHT, 2 * WIDTH).astype(np.float32), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_CONSTANT, borderValue=0.3)
        img = cv2.resize(big, (WIDTH, HEIGHT), interpolation=cv2.INTER_AREA)
        img = cv2.GaussianBlur(img, (0, 0), 0.6) * 220 + rng.normal(0, 2, img.shape)
        path = os.path.join(out, f"view-{k:02}.pgm")
        cv2.imwrite(path, np.clip(np.round(img), 0, 255).astype(np.uint8))
        paths.append(path)
    with open(os.path.join(out, "pad.toml"), "w") as fh:
        fh.write(pad_toml())
    return (f, cx, cy, dist), paths


def opencv_fit(touchdown, pad_path, images):
    """cv2.calibrateCamera on touchdown detect's corners, matched to pad.toml by id."""
    with open(pad_path, "rb") as fh:
        pad = tomllib.load(fh)
    layout = {}
    for m in pad["marker"]:
        h, yaw = 0.5 * m["size"], math.radians(m.get("yaw_deg", 0.0))
        c, s = math.cos(yaw), math.sin(yaw)
        layout[(m["family"].lower(), m["id"])] = [
            (c * lx - s * ly + m["x"], s * lx + c * ly + m["y"], 0.0)
            for lx, ly in ((-h, h), (h, h), (h, -h), (-h, -h))]
    families = sorted({m["family"] for m in pad["marker"]})
    cmd = [touchdown, "detect", "--json"] + sum((["--family", f] for f in families), []) + images
    run = subprocess.run(cmd, capture_output=True, text=True, check=True)
    objects, points = [], []
    for line in run.stdout.splitlines():
        obj, img = [], []
        for d in json.loads(line)["detections"]:
            corners = layout.get((d["family"].lower(), d["id"]))
            if corners:
                obj += corners
                img += d["corners"]
        if len(obj) >= 8:
            objects.append(np.array(obj, np.float32))
            points.append(np.array(img, np.float32))
    rms, k, dist, _, _ = cv2.calibrateCamera(objects, points, (WIDTH, HEIGHT), None, None,
                                             flags=cv2.CALIB_FIX_K3)
    return k[0, 0], k[1, 1], k[0, 2], k[1, 2], dist.ravel(), rms, len(objects)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hfov", type=float, default=120.0)
    ap.add_argument("--k1", type=float, default=-0.35)
    ap.add_argument("--k2", type=float, default=None)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="/tmp/lens-opencv")
    ap.add_argument("--touchdown", default=os.path.join(ROOT, "target", "debug", "touchdown"))
    ap.add_argument("--recording", default=None)
    a = ap.parse_args()
    if a.recording:
        pad_path = os.path.join(a.recording, "pad.toml")
        frames = os.path.join(a.recording, "frames")
        images = sorted(os.path.join(frames, n) for n in os.listdir(frames))
        truth = None
        inputs = [a.recording]
    else:
        os.makedirs(a.out, exist_ok=True)
        k2 = -a.k1 / 3 if a.k2 is None else a.k2
        truth, images = render(a.out, a.hfov, a.k1, k2, a.seed)
        pad_path = os.path.join(a.out, "pad.toml")
        inputs = ["--pad", pad_path] + images
    run = subprocess.run([a.touchdown, "calibrate-lens", "--json"] + inputs, capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"calibrate-lens failed: {run.stderr.strip()}")
    ours = json.loads(run.stdout)
    c = ours["camera"]
    rows = [("touchdown calibrate-lens", c["fx"], c["fy"], c["cx"], c["cy"], c["distortion"],
             ours["rms_px"], ours["coverage"]["views"])]
    fx, fy, cx, cy, dist, rms, views = opencv_fit(a.touchdown, pad_path, images)
    rows.append(("cv2.calibrateCamera (same corners)", fx, fy, cx, cy, dist, rms, views))
    print("| method | fx | fy | cx | cy | k1 | k2 | RMS px | views | focal error % | k1 error |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    if truth:
        f, tcx, tcy, tdist = truth
        print(f"| truth | {f:.3f} | {f:.3f} | {tcx:.3f} | {tcy:.3f} | {tdist[0]:.4f} | {tdist[1]:.4f} | | | | |")
    for name, fx, fy, cx, cy, d, rms, views in rows:
        if truth:
            fe = 100 * max(abs(fx - truth[0]), abs(fy - truth[0])) / truth[0]
            ke = abs(d[0] - truth[3][0])
            tail = f"{fe:.3f} | {ke:.4f}"
        else:
            tail = "| "
        print(f"| {name} | {fx:.3f} | {fy:.3f} | {cx:.3f} | {cy:.3f} | {d[0]:.4f} | {d[1]:.4f} | {rms:.3f} | {views} | {tail} |")


if __name__ == "__main__":
    main()
