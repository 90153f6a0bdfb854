"""Makes a FIL camera frame from a simulator recording (`touchdown simulate`): one frame,
resampled from the simulated camera (its camera.toml: pinhole + OpenCV distortion) into the
firmware's nominal OV7725 pinhole model (firmware/src/config.rs: f = 467 px at 640x480, half at
QVGA, principal point at the centre), plus its truth: the pad centre in the camera frame
(x right, y down, z forward), from frames.csv's camera pose in the pad frame, with the
camera's position and the vehicle's attitude (what the emulated autopilot reports).

    python3 -m emu.make_frame RECORDING_DIR INDEX OUT.pgm [qvga|vga]

(VGA: the sensor's whole 640x480 frame; the firmware's DCMI crops it to 640x400 itself.)

Pixels outside the simulated view are mid grey. Run once; the result is committed. The
committed frames come from `touchdown simulate --scenario descent --frames 480
--mount-roll-deg 0 --mount-pitch-deg 0 --vibration-deg 0 --pad nested-field`, frame 479: on the nominal mount,
so that the vehicle attitude in the truth is also the camera's.
"""

import csv
import math
import os
import sys

from .fil import read_pgm

FIRMWARE_F_VGA = 467.0
SIZES = {"qvga": (320, 240), "vga": (640, 480)}


def read_camera(path):
    cam = {}
    with open(path) as f:
        for line in f:
            line = line.split("#")[0].strip()
            if "=" in line:
                key, value = (s.strip() for s in line.split("=", 1))
                cam[key] = [float(v) for v in value.strip("[]").split(",")] \
                    if value.startswith("[") else float(value)
    cam.setdefault("distortion", [0.0] * 5)
    return cam


def distort(cam, x, y):
    k1, k2, p1, p2, k3 = cam["distortion"]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def sample(width, height, pixels, u, v):
    """Bilinear sample at (u, v); 128 outside."""
    if not (0 <= u <= width - 1 and 0 <= v <= height - 1):
        return 128
    u0, v0 = min(int(u), width - 2), min(int(v), height - 2)
    fu, fv = u - u0, v - v0
    p = lambda a, b: pixels[b * width + a]
    top = p(u0, v0) * (1 - fu) + p(u0 + 1, v0) * fu
    bottom = p(u0, v0 + 1) * (1 - fu) + p(u0 + 1, v0 + 1) * fu
    return int(top * (1 - fv) + bottom * fv + 0.5)


def resample(cam, frame, size):
    width, height, pixels = frame
    w, h = size
    f = FIRMWARE_F_VGA * w / 640
    cx, cy = (w - 1) / 2, (h - 1) / 2
    out = bytearray(w * h)
    for v in range(h):
        for u in range(w):
            xd, yd = distort(cam, (u - cx) / f, (v - cy) / f)
            out[v * w + u] = sample(width, height, pixels,
                                    cam["cx"] + cam["fx"] * xd, cam["cy"] + cam["fy"] * yd)
    return bytes(out)


def rotate_inverse(q, v):
    """R(q)^T v for the unit quaternion q = (w, x, y, z)."""
    w, x, y, z = q
    r = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
    return [sum(r[i][j] * v[i] for i in range(3)) for j in range(3)]


def truth_of(recording, index):
    """The camera's position in the pad frame, the pad centre in the camera frame, and the
    vehicle's body FRD to NED attitude (w, x, y, z; NED: north = pad +y, east = pad +x)."""
    with open(os.path.join(recording, "frames.csv")) as f:
        for row in csv.DictReader(f):
            if int(row["index"]) == index:
                pos = [float(row[k]) for k in ("cam_x", "cam_y", "cam_z")]
                q = [float(row[k]) for k in ("cam_qw", "cam_qx", "cam_qy", "cam_qz")]
                pad = rotate_inverse(q, [-p for p in pos])
                vehicle = [float(row[k]) for k in ("veh_qw", "veh_qx", "veh_qy", "veh_qz")]
                return pos, pad, vehicle
    raise KeyError(f"frame {index} not in frames.csv")


def main(argv):
    recording, index, out = argv[0], int(argv[1]), argv[2]
    size = SIZES[argv[3] if len(argv) > 3 else "qvga"]
    cam = read_camera(os.path.join(recording, "camera.toml"))
    frame = read_pgm(os.path.join(recording, "frames", f"{index:06d}.pgm"))
    pixels = resample(cam, frame, size)
    with open(out, "wb") as f:
        f.write(b"P5\n%d %d\n255\n" % size + pixels)
    pos, pad, vehicle = truth_of(recording, index)
    with open(os.path.splitext(out)[0] + ".txt", "w") as f:
        f.write(f"# {os.path.basename(recording)} frame {index}, resampled to the firmware's "
                f"{size[0]}x{size[1]} pinhole (f {FIRMWARE_F_VGA * size[0] / 640} px)\n")
        f.write(f"# camera in the pad frame: {pos[0]:.4f} {pos[1]:.4f} {pos[2]:.4f} m, range "
                f"{math.sqrt(sum(p * p for p in pos)):.4f} m\n")
        for axis, value in zip("xyz", pad):
            f.write(f"pad_cam_{axis} = {value:.4f}\n")
        f.write("# the camera in the pad frame (m), and the vehicle's body FRD to NED attitude at\n"
                "# the frame (NED: north = pad +y, east = pad +x, down = pad -z): what the\n"
                "# emulated autopilot reports (autopilot.py)\n")
        for axis, value in zip("xyz", pos):
            f.write(f"cam_{axis} = {value:.4f}\n")
        for part, value in zip("wxyz", vehicle):
            f.write(f"veh_q{part} = {value:.6f}\n")


if __name__ == "__main__":
    main(sys.argv[1:])
