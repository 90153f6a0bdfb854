#!/usr/bin/env python3
"""Compare touchdown's detector with AprilTag 3 and OpenCV ArUco on the same images.

Usage
-----
    pip install pupil-apriltags opencv-contrib-python-headless==4.14.0.94
    python3 scripts/compare_peers.py                       # the shared data sets
    python3 scripts/compare_peers.py --repeats 20 more.png some/dir --family aruco_6x6_250
    python3 scripts/compare_peers.py --stills DIR --repeats 1 --rounds 1   # a still set

Images: AprilTag 3's three test photos (tag36h11, 47 markers, all id 0), ViSP's rendered
benchmark at 640x480 and 1920x1080 for tag16h5 / tag25h9 / tag36h11 (ids 0-4) and ViSP's
AprilTag.png photo (tag36h11, ids 8-19), read from `$TOUCHDOWN_DATA` or `../shared/data`
next to the repository (`--data DIR` overrides); the simulator's four landing frames of the
Cortex-M7 benchmark (`bench/m7/frames`, 320x240 and 640x480, tag36h11 and aruco_6x6_250 on
textured ground, truth from their placements; AprilTag 3 has no aruco dictionary); plus any
image files or directories given on the command line (searched for `--family`, default
tag36h11, with no expected ids).

Detectors, each in its own subprocess (so one library's threads, allocator or SIMD dispatch
cannot affect another's timing):
- touchdown: `touchdown detect --json --family F`, built with
  `cargo build --release -p touchdown-cli` (or `--touchdown PATH`); its `time_ms`;
- AprilTag 3 (pupil_apriltags): the right family, quad_decimate 1 and 2, refine_edges on,
  nthreads 1;
- OpenCV ArUco (cv2.aruco.ArucoDetector) with the matching DICT_APRILTAG_* / DICT_* dictionary
  and default parameters (no corner refinement), and again with CORNER_REFINE_SUBPIX; one
  thread (`cv2.setNumThreads(1)`: OpenCV otherwise spreads the thresholding over every core,
  and the other two detectors run on one).

Timing: every detector is given the decoded grey image (file decoding is never timed) and
runs it `--repeats` times in a row (default 10) in one warm process; the median is that
round's time. The detectors take turns for `--rounds` rounds (default 5), and an image's
time is the FASTEST of its rounds (load only adds time), so that a spell of load on the
machine does not land on one detector's runs alone (single runs of this script on a shared
2-core machine moved touchdown's total between 16 and 24 ms, and the ratios by a third).
Times are wall-clock milliseconds on this machine, every detector on one thread.

Per image the table gives each detector's time, its recall (expected markers found with the
right id / expected; where reference corners exist a detection must also lie on the marker,
centre within half its edge), wrong ids (detections with an id not expected in the image)
and other detections (any further detection), and the time ratios to touchdown (above 1 =
touchdown is faster). A total over all images follows.

`--stills DIR` compares on a still set written by `cargo run --release -p
touchdown-host-tests --example hard_stills -- --write DIR` (its `truth.csv`: file, family, id,
the four corners) instead of the shared data: recall and wrong ids per renderer and class
(from the file names), over the stills each detector could run (OpenCV has no
tagStandard41h12, AprilTag 3 no ArUco family). touchdown runs without `--camera` there, as the
peers do (its long test gives the wide-lens stills their lens).

The references are other detectors' output, not complete truth: AprilTag's photos hold more
id-0 tags than its 47 (the cubes' steep top faces, tiny distant faces), so on those photos
"other" mostly counts real markers the reference omits; on ViSP's images it counts
duplicates and false positives.
"""

import argparse
import glob
import json
import os
import re
import statistics
import subprocess
import sys
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".pgm", ".ppm", ".bmp")

# Family names (the contract's) -> OpenCV dictionary attribute; pupil_apriltags knows the
# AprilTag families under their own names.
OPENCV_DICTIONARIES = {
    "tag16h5": "DICT_APRILTAG_16h5",
    "tag25h9": "DICT_APRILTAG_25h9",
    "tag36h10": "DICT_APRILTAG_36h10",
    "tag36h11": "DICT_APRILTAG_36h11",
    "aruco_original": "DICT_ARUCO_ORIGINAL",
    "aruco_mip_36h12": "DICT_ARUCO_MIP_36h12",
}
for _bits in (4, 5, 6, 7):
    for _count in (50, 100, 250, 1000):
        OPENCV_DICTIONARIES["aruco_%dx%d_%d" % (_bits, _bits, _count)] = "DICT_%dX%d_%d" % (_bits, _bits, _count)
APRILTAG_FAMILIES = {"tag16h5", "tag25h9", "tag36h11", "tagStandard41h12"}


# ----------------------------------------------------------------------------------------
# Workers: run in a subprocess, print one JSON object per image.


def worker_main(args):
    import cv2  # noqa: F401  (both workers decode with OpenCV)

    images = []
    for path in args.images:
        img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if img is None:
            print(json.dumps({"image": path, "error": "cannot read"}), flush=True)
            continue
        images.append((path, img))

    if args.worker == "apriltag":
        import pupil_apriltags

        detector = pupil_apriltags.Detector(
            families=args.family,
            nthreads=1,
            quad_decimate=float(args.decimate),
            refine_edges=1,
        )

        def detect(img):
            return [(d.tag_id, d.corners.tolist()) for d in detector.detect(img)]

    else:
        import cv2

        # Single-threaded like the other two (its default is one thread per core).
        cv2.setNumThreads(1)
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, OPENCV_DICTIONARIES[args.family]))
        params = cv2.aruco.DetectorParameters()
        if args.subpix:
            params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        detector = cv2.aruco.ArucoDetector(dictionary, params)

        def detect(img):
            corners, ids, _ = detector.detectMarkers(img)
            if ids is None:
                return []
            return [(int(i), c.reshape(4, 2).tolist()) for i, c in zip(ids.ravel(), corners)]

    for path, img in images:
        times = []
        found = []
        for _ in range(args.repeats):
            started = time.perf_counter()
            found = detect(img)
            times.append((time.perf_counter() - started) * 1e3)
        print(
            json.dumps(
                {
                    "image": path,
                    "times_ms": times,
                    "detections": [{"id": i, "corners": c} for i, c in found],
                }
            ),
            flush=True,
        )


# ----------------------------------------------------------------------------------------
# Driver.


class Case:
    """One image, its family and what should be found in it."""

    def __init__(self, path, family, expected_ids=None, reference_corners=None, group=None):
        self.path = path
        self.family = family
        # A still set's renderer and class, for its summary.
        self.group = group
        # None: unknown (extra images). Else a list of ids (repeated ids allowed).
        self.expected_ids = expected_ids
        # Optional list of (id, 4 corners) in any pixel convention: used only for centres.
        self.reference = reference_corners


def numbers(line):
    return [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?", line)]


def builtin_cases(data):
    cases = []
    for jpg in sorted(glob.glob(os.path.join(data, "apriltag-test", "*.jpg"))):
        reference = []
        with open(os.path.splitext(jpg)[0] + ".txt") as f:
            for line in f:
                v = numbers(line)
                if len(v) == 9:
                    reference.append((int(v[0]), [v[1:3], v[3:5], v[5:7], v[7:9]]))
        cases.append(Case(jpg, "tag36h11", [r[0] for r in reference], reference))
    visp = os.path.join(data, "visp-apriltag")
    for visp_name, family in (("tag16_05", "tag16h5"), ("tag25_09", "tag25h9"), ("tag36_11", "tag36h11")):
        small = os.path.join(visp, "benchmark-640x480")
        reference = read_visp_corners(os.path.join(small, "corners_%s.txt" % visp_name), swap=False)
        cases.append(Case(os.path.join(small, "%s_640x480.png" % visp_name), family, list(range(5)), reference))
    for visp_name, family in (("tag16_05", "tag16h5"), ("tag25_09", "tag25h9"), ("tag36_11", "tag36h11")):
        big = os.path.join(visp, "benchmark-1920x1080", "%s_1920x1080.png" % visp_name)
        cases.append(Case(big, family, list(range(5))))
    reference = read_visp_corners(os.path.join(visp, "ground_truth_detection.txt"), swap=True)
    cases.append(Case(os.path.join(visp, "AprilTag.png"), "tag36h11", list(range(8, 20)), reference))
    cases += simulator_cases()
    return [c for c in cases if os.path.isfile(c.path)]


# The simulator's landing frames of the Cortex-M7 benchmark (bench/m7/frames, rendered by
# host-tests/examples/m7_frames.rs: textured ground, blur, sensor noise): per frame and
# family, each marker's id, true centre (pixels, (0, 0) = centre of the top-left pixel) and
# edge (pixels), copied from the example's placements.
SIMULATOR_FRAMES = [
    ("qvga-landing-1.pgm", "tag36h11", [(7, 171.3, 113.6, 40.0)]),
    ("qvga-multi-6.pgm", "tag36h11", [(0, 62.4, 66.7, 56.0), (1, 160.2, 58.3, 32.0), (2, 258.7, 61.1, 20.0)]),
    ("qvga-multi-6.pgm", "aruco_6x6_250", [(3, 70.6, 175.2, 44.0), (4, 165.3, 178.8, 26.0), (5, 255.1, 172.4, 18.0)]),
    ("qvga-far-1.pgm", "tag36h11", [(11, 149.6, 127.3, 14.0)]),
    ("vga-landing-3.pgm", "tag36h11", [(21, 300.4, 230.9, 96.0), (22, 505.2, 110.7, 40.0)]),
    ("vga-landing-3.pgm", "aruco_6x6_250", [(9, 140.8, 370.3, 64.0)]),
]


def simulator_cases():
    """The simulator frames with their truth, as reference squares around the true centres
    (the score only uses a reference's centre and edge)."""
    cases = []
    for name, family, markers in SIMULATOR_FRAMES:
        reference = []
        for tag_id, x, y, edge in markers:
            h = edge / 2
            reference.append((tag_id, [[x - h, y - h], [x + h, y - h], [x + h, y + h], [x - h, y + h]]))
        path = os.path.join(REPO, "bench", "m7", "frames", name)
        cases.append(Case(path, family, [m[0] for m in markers], reference))
    return cases


def read_visp_corners(path, swap):
    """ViSP corner files: an id line (`3` or `36h11_id:_8`), then four `x y` (`y x` if swap)."""
    if not os.path.isfile(path):
        return None
    with open(path) as f:
        lines = [l for l in f.read().splitlines() if l.strip()]
    out = []
    for k in range(0, len(lines) - 4, 5):
        tag_id = int(re.findall(r"\d+", lines[k])[-1])
        corners = [numbers(l)[:2] for l in lines[k + 1 : k + 5]]
        if swap:
            corners = [[y, x] for x, y in corners]
        out.append((tag_id, corners))
    return out


def extra_cases(paths, family):
    cases = []
    for path in paths:
        if os.path.isdir(path):
            for name in sorted(os.listdir(path)):
                if name.lower().endswith(IMAGE_EXTENSIONS):
                    cases.append(Case(os.path.join(path, name), family))
        elif os.path.isfile(path):
            cases.append(Case(path, family))
        else:
            sys.exit("error: %s: no such file or directory" % path)
    return cases


def still_cases(directory):
    """A still set's truth.csv: file, family, id, x0, y0, ..., x3, y3 (contract corners)."""
    truth = os.path.join(directory, "truth.csv")
    if not os.path.isfile(truth):
        sys.exit("error: %s: no truth.csv (write a still set with the hard_stills example's --write)" % directory)
    cases = []
    with open(truth) as f:
        for line_number, line in enumerate(f.read().splitlines()[1:], start=2):
            fields = line.split(",")
            if len(fields) != 11:
                sys.exit("error: %s:%d: expected 11 fields, found %d" % (truth, line_number, len(fields)))
            name, family, tag_id = fields[0], fields[1], int(fields[2])
            v = [float(x) for x in fields[3:]]
            corners = [v[0:2], v[2:4], v[4:6], v[6:8]]
            group = re.sub(r"-\d+\.png$", "", name)
            cases.append(Case(os.path.join(directory, name), family, [tag_id], [(tag_id, corners)], group))
    return cases


def print_still_summary(cases, results, detectors):
    """Recall and wrong ids per detector and still group, over the stills each one ran."""
    groups = sorted({c.group for c in cases})
    print("%-28s %-24s %10s %6s" % ("detector", "renderer-class", "recall", "wrong"))
    for name, _ in detectors:
        for group in groups:
            found = expected = wrong = 0
            for case in (c for c in cases if c.group == group):
                result = results[(name, case.family)]
                entry = None if isinstance(result, str) else result.get(case.path)
                if entry is None:
                    continue
                f, e, w, _ = score(case, entry["detections"])
                found, expected, wrong = found + f, expected + e, wrong + w
            if expected:
                print("%-28s %-24s %10s %6d" % (name, group, "%d/%d" % (found, expected), wrong))


def run_worker(extra_args, images, repeats, family):
    command = [sys.executable, os.path.abspath(__file__), "--worker"] + extra_args
    command += ["--family", family, "--repeats", str(repeats), "--"] + images
    return collect(command)


def collect(command):
    """Runs a detector process; returns {image: {"ms": median, "detections": [...]}}, or an
    error string when it produced nothing."""
    try:
        done = subprocess.run(command, capture_output=True, text=True, check=False)
    except OSError as e:
        return "cannot run %s: %s" % (command[0], e)
    results = {}
    for line in done.stdout.splitlines():
        record = json.loads(line)
        if "error" in record:
            continue
        entry = results.setdefault(record["image"], {"times": [], "detections": record["detections"]})
        entry["times"].extend(record["times_ms"] if "times_ms" in record else [record["time_ms"]])
    for entry in results.values():
        entry["ms"] = statistics.median(entry["times"])
    for line in done.stderr.strip().splitlines():
        # Unreadable extra images and the like: show them, keep the other results.
        if done.returncode != 0:
            print("  %s" % line, file=sys.stderr)
    if not results and done.returncode != 0:
        return (done.stderr.strip().splitlines() or ["exit status %d" % done.returncode])[-1]
    return results


def merge_round(results, key, result):
    """Adds one round's `result` (as from `collect`) to `results[key]`: each image's round
    medians are kept in "rounds" and "ms" becomes the smallest (load on the machine only ever
    adds time, so the fastest round is the closest to the detector's own cost); the first
    round's detections stand (every detector here is deterministic). An error string is kept
    only when no round produced anything."""
    if isinstance(result, str):
        results.setdefault(key, result)
        return
    merged = results.get(key)
    if not isinstance(merged, dict):
        merged = results[key] = {}
    for image, entry in result.items():
        kept = merged.setdefault(image, {"detections": entry["detections"], "rounds": []})
        kept["rounds"].append(entry["ms"])
        kept["ms"] = min(kept["rounds"])


def run_touchdown(binary, images, repeats, family):
    # Each image repeated in one process: the detector and its work memory stay warm, as in
    # the peers' loops; time_ms excludes decoding.
    command = [binary, "detect", "--json", "--family", family]
    for image in images:
        command += [image] * repeats
    return collect(command)


def score(case, detections):
    """(found, expected or None, wrong ids, other detections)."""
    if case.expected_ids is None:
        return len(detections), None, 0, 0
    expected = list(case.expected_ids)
    used = [False] * len(detections)
    found = 0
    if case.reference:
        for ref_id, ref in case.reference:
            cx = sum(p[0] for p in ref) / 4
            cy = sum(p[1] for p in ref) / 4
            edge = max(((ref[0][0] - ref[1][0]) ** 2 + (ref[0][1] - ref[1][1]) ** 2) ** 0.5,
                       ((ref[1][0] - ref[2][0]) ** 2 + (ref[1][1] - ref[2][1]) ** 2) ** 0.5)
            best, best_gap = None, 0.5 * edge
            for k, d in enumerate(detections):
                if used[k] or d["id"] != ref_id:
                    continue
                dx = sum(p[0] for p in d["corners"]) / 4 - cx
                dy = sum(p[1] for p in d["corners"]) / 4 - cy
                gap = (dx * dx + dy * dy) ** 0.5
                if gap <= best_gap:
                    best, best_gap = k, gap
            if best is not None:
                used[best] = True
                found += 1
    else:
        remaining = list(expected)
        for k, d in enumerate(detections):
            if d["id"] in remaining:
                remaining.remove(d["id"])
                used[k] = True
                found += 1
    wrong = sum(1 for d in detections if d["id"] not in expected)
    other = used.count(False)
    return found, len(expected), wrong, other


def fmt_ratio(peer_ms, touchdown_ms):
    if peer_ms is None or touchdown_ms is None or touchdown_ms <= 0:
        return "-"
    return "%.2f" % (peer_ms / touchdown_ms)


def print_table(title, rows, touchdown_ms):
    print("\n== %s" % title)
    print("%-28s %10s %9s %6s %6s %12s" % ("detector", "ms", "recall", "wrong", "other", "ms / td"))
    for name, ms, found, expected, wrong, other, error in rows:
        if error:
            print("%-28s %s" % (name, error))
            continue
        recall = "%d/%d" % (found, expected) if expected is not None else "%d found" % found
        print("%-28s %10.2f %9s %6d %6d %12s" % (name, ms, recall, wrong, other, fmt_ratio(ms, touchdown_ms)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("paths", nargs="*", help="extra image files or directories")
    parser.add_argument("--family", default="tag36h11", help="family of the extra images (default tag36h11)")
    parser.add_argument("--repeats", type=int, default=10, help="runs per image and round (their median is the round's time)")
    parser.add_argument("--rounds", type=int, default=5,
                        help="rounds in which the detectors take turns; an image's time is the fastest of its rounds")
    parser.add_argument("--data", help="shared data directory (default $TOUCHDOWN_DATA or ../shared/data)")
    parser.add_argument("--touchdown", help="touchdown binary (default: build it with cargo --release)")
    parser.add_argument("--only-extra", action="store_true", help="skip the shared data sets")
    parser.add_argument("--stills", metavar="DIR",
                        help="a still set (hard_stills --write DIR) instead of the shared data: a summary per class")
    # Worker mode (internal).
    parser.add_argument("--worker", choices=["apriltag", "opencv"], help=argparse.SUPPRESS)
    parser.add_argument("--decimate", default="1", help=argparse.SUPPRESS)
    parser.add_argument("--subpix", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        args.images = args.paths
        worker_main(args)
        return
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    if args.rounds < 1:
        parser.error("--rounds must be at least 1")

    data = args.data or os.environ.get("TOUCHDOWN_DATA") or os.path.join(os.path.dirname(REPO), "shared", "data")
    if args.stills and args.paths:
        parser.error("--stills takes no further images")
    if args.stills:
        cases = still_cases(args.stills)
    else:
        cases = [] if args.only_extra else builtin_cases(data)
    if not args.only_extra and not args.stills and not cases:
        print("note: no shared data at %s; only extra images are compared" % data, file=sys.stderr)
    cases += extra_cases(args.paths, args.family)
    if not cases:
        sys.exit("error: no images to compare")

    binary = args.touchdown or build_touchdown()

    detectors = [
        ("touchdown", lambda imgs, fam: run_touchdown(binary, imgs, args.repeats, fam)),
        ("apriltag3 decimate 1", lambda imgs, fam: run_worker(["apriltag", "--decimate", "1"], imgs, args.repeats, fam)
         if fam in APRILTAG_FAMILIES else "family not supported by AprilTag"),
        ("apriltag3 decimate 2", lambda imgs, fam: run_worker(["apriltag", "--decimate", "2"], imgs, args.repeats, fam)
         if fam in APRILTAG_FAMILIES else "family not supported by AprilTag"),
        ("opencv aruco", lambda imgs, fam: run_worker(["opencv"], imgs, args.repeats, fam)
         if fam in OPENCV_DICTIONARIES else "family not in OpenCV"),
        ("opencv aruco + subpix", lambda imgs, fam: run_worker(["opencv", "--subpix"], imgs, args.repeats, fam)
         if fam in OPENCV_DICTIONARIES else "family not in OpenCV"),
    ]

    # One process per detector and family, covering all that family's images; the detectors
    # take turns, round after round, so that a spell of load on this machine (another
    # process, a busy neighbour of a virtual machine) slows one round of each rather than all
    # the runs of whichever detector was running then. An image's time is the fastest of its
    # rounds' medians.
    families = sorted({c.family for c in cases})
    results = {}  # (detector, family) -> dict or error string
    for round_number in range(1, args.rounds + 1):
        for name, run in detectors:
            for family in families:
                images = [c.path for c in cases if c.family == family]
                print("round %d/%d: running %s on %d %s image(s)..."
                      % (round_number, args.rounds, name, len(images), family), file=sys.stderr, flush=True)
                merge_round(results, (name, family), run(images, family))

    if args.stills:
        print_still_summary(cases, results, detectors)
        return

    print("Times: per image the fastest of %d rounds' medians of %d runs, ms, decoding excluded; "
          "ms / td = detector time / touchdown time (above 1: touchdown is faster)." % (args.rounds, args.repeats))
    # name -> [ms, found, expected, wrong, other, touchdown ms on the same images, error]
    totals = {name: [0.0, 0, 0, 0, 0, 0.0, None] for name, _ in detectors}
    for case in cases:
        rows = []
        touchdown_entry = None
        if not isinstance(results[("touchdown", case.family)], str):
            touchdown_entry = results[("touchdown", case.family)].get(case.path)
        touchdown_ms = touchdown_entry["ms"] if touchdown_entry else None
        for name, _ in detectors:
            result = results[(name, case.family)]
            if isinstance(result, str):
                rows.append((name, None, 0, None, 0, 0, result))
                totals[name][6] = result
                continue
            entry = result.get(case.path)
            if entry is None:
                rows.append((name, None, 0, None, 0, 0, "no result"))
                continue
            found, expected, wrong, other = score(case, entry["detections"])
            rows.append((name, entry["ms"], found, expected, wrong, other, None))
            total = totals[name]
            total[0] += entry["ms"]
            total[1] += found
            total[2] += expected or 0
            total[3] += wrong
            total[4] += other
            total[5] += touchdown_ms or 0.0
        shown = case.path
        if os.path.abspath(case.path).startswith(os.path.abspath(data) + os.sep):
            shown = os.path.relpath(case.path, data)
        expected_text = "%d expected" % len(case.expected_ids) if case.expected_ids is not None else "no expected ids"
        print_table("%s (%s, %s)" % (shown, case.family, expected_text), rows, touchdown_ms)

    print("\n== all %d images (times summed; ms / td over the images both ran; recall over images "
          "with expected ids)" % len(cases))
    print("%-28s %10s %9s %6s %6s %12s" % ("detector", "ms", "recall", "wrong", "other", "ms / td"))
    for name, _ in detectors:
        ms, found, expected, wrong, other, touchdown_ms, error = totals[name]
        note = " (skipped some images: %s)" % error if error else ""
        print("%-28s %10.2f %9s %6d %6d %12s%s" % (name, ms, "%d/%d" % (found, expected), wrong, other,
                                                 fmt_ratio(ms, touchdown_ms), note))


def build_touchdown():
    print("building touchdown (cargo build --release -p touchdown-cli)...", file=sys.stderr, flush=True)
    subprocess.run(["cargo", "build", "--release", "-p", "touchdown-cli"], cwd=REPO, check=True)
    metadata = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"], cwd=REPO,
                              check=True, capture_output=True, text=True)
    target = json.loads(metadata.stdout)["target_directory"]
    binary = os.path.join(target, "release", "touchdown" + (".exe" if os.name == "nt" else ""))
    if not os.path.isfile(binary):
        sys.exit("error: %s was not built" % binary)
    return binary


if __name__ == "__main__":
    main()
