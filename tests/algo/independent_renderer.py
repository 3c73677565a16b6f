#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Frames from a second, independent renderer, solved by `dockpose solve` as a new user would.

dockpose's own renderer (algo/synth) and its pipeline grew up together; a threshold tuned to one
would pass every test written with the other. This renderer shares none of its code or its
models: OpenCV projects the LEDs (cv2.projectPoints), a spot is a blurred disc with a Moffat
halo (heavier wings than a Gaussian), the sensor has shot noise, read noise and row noise, the
background vignettes and carries low-frequency blotches, clutter is specular ellipses, streaks,
window-sized patches and LED-like dots, and the whole frame may be motion-blurred. Targets: the
four of tests/data and one made here (an irregular hinge); cameras: the three of tests/data and
two made here (640x480 with mild pincushion, 1024x768 with strong barrel distortion).

Each frame's reported pose is compared with the truth, modulo the target's own symmetries:
correct within 2 degrees and max(5 mm, 2 % of range); anything else found is WRONG. Exit status
1 when any pose is wrong or any target-free frame gives a pose, else 0; the found shares are
printed (they are measurements, not pass marks).

Usage: independent_renderer.py --dockpose BIN --data tests/data [--frames N] [--seed S]
       [--out DIR] [--keep]
"""
import argparse
import itertools
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile

import cv2
import numpy as np

CATEGORIES = ("clean", "clutter", "heavy", "occluded", "dim", "blur", "bright", "target-free")

EXTRA_CAMERAS = {
    "cam640-pincushion": {"width": 640, "height": 480, "fx": 520.0, "fy": 522.0, "cx": 322.3,
                          "cy": 236.9, "k1": 0.06, "k2": 0.0, "p1": -0.0004, "p2": 0.0003},
    "cam1024-barrel": {"width": 1024, "height": 768, "fx": 560.0, "fy": 560.0, "cx": 509.6,
                       "cy": 386.2, "k1": -0.26, "k2": 0.06, "p1": 0.0, "p2": 0.0},
}


def hingeTarget():
    """An irregular two-face hinge made here: faces of different sizes, 100 degrees apart."""
    a = np.array([[-70.0, -42.0, 0.0], [4.0, -50.0, 0.0], [0.0, 47.0, 0.0], [-64.0, 38.0, 0.0]])
    ang = math.radians(80.0)
    b2 = np.array([4.0 + 92.0 * math.cos(ang), -44.0, -92.0 * math.sin(ang)])
    b3 = np.array([0.0 + 85.0 * math.cos(ang), 52.0, -85.0 * math.sin(ang)])
    points = np.vstack([a, b2, b3])
    points -= points.mean(axis=0)
    return {"name": "hinge", "units": "mm", "points": np.round(points, 3).tolist(),
            "faces": [[0, 1, 2, 3], [1, 4, 5, 2]]}


def faceNormals(points, faces):
    """Outward unit normal of each face: away from the centroid of all LEDs."""
    centre = points.mean(axis=0)
    normals = []
    for face in faces:
        p = points[face]
        n = np.cross(p[2] - p[0], p[3] - p[1])
        n /= np.linalg.norm(n)
        if np.dot(n, p.mean(axis=0) - centre) < 0:
            n = -n
        normals.append(n)
    return np.array(normals)


def symmetries(points):
    """Proper rigid motions mapping the LED set onto itself (as (R, t)), identity included."""
    n = len(points)
    d = np.linalg.norm(points[:, None] - points[None], axis=2)
    found = []
    for perm in itertools.permutations(range(n)):
        if not np.allclose(d, d[np.ix_(perm, perm)], atol=0.5):
            continue
        q = points[list(perm)]
        pc, qc = points.mean(axis=0), q.mean(axis=0)
        u, _, vt = np.linalg.svd((points - pc).T @ (q - qc))
        r = vt.T @ u.T
        if np.linalg.det(r) < 0:
            continue
        t = qc - r @ pc
        if np.sqrt(np.mean(np.sum((points @ r.T + t - q) ** 2, axis=1))) < 0.5:
            found.append((r, t))
    return found


def quatToR(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def randomUnitInCone(rng, axis, max_deg):
    """A direction within max_deg of axis, uniform on the spherical cap."""
    cos_max = math.cos(math.radians(max_deg))
    z = rng.uniform(cos_max, 1.0)
    phi = rng.uniform(0, 2 * math.pi)
    s = math.sqrt(1 - z * z)
    local = np.array([s * math.cos(phi), s * math.sin(phi), z])
    a = axis / np.linalg.norm(axis)
    helper = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    return local[0] * e1 + local[1] * e2 + local[2] * a


def lookAt(cam_pos, target, roll_deg):
    """R, t (X_c = R X_t + t) of a camera at cam_pos looking at target, rolled about its axis."""
    z = target - cam_pos
    z /= np.linalg.norm(z)
    up = np.array([0, 0, 1.0]) if abs(z[2]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r = np.vstack([x, y, z])
    c, s = math.cos(math.radians(roll_deg)), math.sin(math.radians(roll_deg))
    r = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ r
    return r, -r @ cam_pos


class Camera:
    def __init__(self, spec):
        self.spec = spec
        self.w, self.h = spec["width"], spec["height"]
        self.k = np.array([[spec["fx"], 0, spec["cx"]], [0, spec["fy"], spec["cy"]], [0, 0, 1.0]])
        self.dist = np.array([spec["k1"], spec["k2"], spec["p1"], spec["p2"]])

    def project(self, points_c):
        uv, _ = cv2.projectPoints(points_c.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), self.k,
                                  self.dist)
        return uv.reshape(-1, 2)

    def maxNormalisedRadius(self):
        """Undistorted radius of the frame's corners (the projection is only trusted inside)."""
        corners = np.array([[0, 0], [self.w - 1, 0], [0, self.h - 1], [self.w - 1, self.h - 1]],
                           dtype=np.float64).reshape(-1, 1, 2)
        und = cv2.undistortPoints(corners, self.k, self.dist).reshape(-1, 2)
        return float(np.max(np.linalg.norm(und, axis=1)))


def drawSpot(img, u, v, peak, disc_px, blur_px, halo=0.12):
    """A disc of radius disc_px blurred by blur_px (sigma) plus a Moffat halo; peak is the
    profile's maximum in levels (before clipping). 4x4 samples per pixel."""
    reach = disc_px + 6.0 * blur_px + 8.0
    x0, x1 = int(math.floor(u - reach)), int(math.ceil(u + reach)) + 1
    y0, y1 = int(math.floor(v - reach)), int(math.ceil(v + reach)) + 1
    cx0, cx1, cy0, cy1 = max(x0, 0), min(x1, img.shape[1]), max(y0, 0), min(y1, img.shape[0])
    if cx0 >= cx1 or cy0 >= cy1:
        return
    sub = (np.arange(4) + 0.5) / 4.0 - 0.5
    xs = (np.arange(cx0, cx1)[:, None] + sub[None]).reshape(-1)
    ys = (np.arange(cy0, cy1)[:, None] + sub[None]).reshape(-1)
    dx = xs[None, :] - u
    dy = ys[:, None] - v
    d = np.sqrt(dx * dx + dy * dy)
    core = 0.5 * erfcArray((d - disc_px) / (math.sqrt(2.0) * blur_px))
    alpha = max(blur_px, 0.5) * 2.5 + disc_px
    moffat = (1.0 + (d / alpha) ** 2) ** -2.5
    prof = (1.0 - halo) * core + halo * moffat
    prof = prof.reshape(cy1 - cy0, 4, cx1 - cx0, 4).mean(axis=(1, 3))
    centre = (1.0 - halo) * 0.5 * erfcArray(np.array([-disc_px / (math.sqrt(2.0) * blur_px)]))[0] \
        + halo
    img[cy0:cy1, cx0:cx1] += peak * prof / centre


def erfcArray(x):
    # Abramowitz-Stegun 7.1.26 (|error| < 1.5e-7), vectorised.
    s = np.sign(x)
    a = np.abs(x)
    t = 1.0 / (1.0 + 0.3275911 * a)
    y = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027
                                                                          + t * 1.061405429))))
    erf = 1.0 - y * np.exp(-a * a)
    return 1.0 - s * erf


def addBlurred(img, x0, y0, x1, y1, sigma, draw):
    """Draw into a local layer (its origin at x0, y0; 1/16 px coordinates), blur, add."""
    m = int(math.ceil(4 * sigma)) + 2
    x0, y0 = max(int(x0) - m, 0), max(int(y0) - m, 0)
    x1, y1 = min(int(x1) + m + 1, img.shape[1]), min(int(y1) + m + 1, img.shape[0])
    if x0 >= x1 or y0 >= y1:
        return
    layer = np.zeros((y1 - y0, x1 - x0), np.float64)
    draw(layer, lambda x, y: (int(round((x - x0) * 16)), int(round((y - y0) * 16))))
    img[y0:y1, x0:x1] += cv2.GaussianBlur(layer, (0, 0), sigma)


def drawEllipse(img, rng, u, v, level):
    """A specular highlight: a filled, blurred ellipse."""
    a, b = rng.uniform(3, 30), rng.uniform(1.5, 10)
    ang = rng.uniform(0, 180)
    addBlurred(img, u - a, v - a, u + a, v + a, rng.uniform(0.7, 3.0),
               lambda layer, at: cv2.ellipse(layer, at(u, v), (int(a * 16), int(b * 16)), ang,
                                             0, 360, float(level), -1, cv2.LINE_AA, 4))


def drawStreak(img, rng, u, v, level):
    """A glint along an edge: a line 20-150 px long, 1-3 px wide."""
    half, ang = 0.5 * rng.uniform(20, 150), rng.uniform(0, math.pi)
    du, dv = half * math.cos(ang), half * math.sin(ang)
    width = int(rng.integers(1, 4))
    addBlurred(img, u - abs(du), v - abs(dv), u + abs(du), v + abs(dv), 1.0,
               lambda layer, at: cv2.line(layer, at(u - du, v - dv), at(u + du, v + dv),
                                          float(level), width, cv2.LINE_AA, 4))


def drawPatch(img, rng, u, v, level):
    """A window's reflection: a large, soft-edged quadrilateral, often clipping."""
    w, h = rng.uniform(40, 220), rng.uniform(30, 160)
    pts = [(u - w / 2, v - h / 2), (u + w / 2, v - h / 2 + rng.uniform(-20, 20)),
           (u + w / 2, v + h / 2), (u - w / 2 + rng.uniform(-20, 20), v + h / 2)]
    addBlurred(img, u - w / 2 - 20, v - h / 2 - 20, u + w / 2 + 20, v + h / 2 + 20,
               rng.uniform(2.0, 8.0),
               lambda layer, at: cv2.fillConvexPoly(layer, np.array([at(x, y) for x, y in pts],
                                                                    np.int32),
                                                    float(level), cv2.LINE_AA, 4))


def background(rng, cam):
    h, w = cam.h, cam.w
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    base = rng.uniform(4, 45)
    img = base + rng.uniform(-20, 20) * (xx / w - 0.5) + rng.uniform(-20, 20) * (yy / h - 0.5)
    r2 = ((xx - cam.spec["cx"]) ** 2 + (yy - cam.spec["cy"]) ** 2) / (cam.spec["fx"] ** 2)
    strength = rng.uniform(0.0, 1.0)  # vignetting (cos^4), on some frames strong
    img *= (1.0 - strength) + strength / (1.0 + r2) ** 2
    img = np.clip(img, 0, None)
    for _ in range(int(rng.integers(0, 4))):
        cu, cv_, s = rng.uniform(0, w), rng.uniform(0, h), rng.uniform(80, 320)
        img += rng.uniform(-12, 18) * np.exp(-((xx - cu) ** 2 + (yy - cv_) ** 2) / (2 * s * s))
    return np.clip(img, 0, None)


def sensor(rng, img):
    gain = rng.uniform(0.25, 1.0)  # levels per electron
    electrons = rng.poisson(np.clip(img, 0, None) / gain)
    out = electrons * gain + rng.normal(0, rng.uniform(0.8, 3.0), img.shape)
    out += rng.normal(0, rng.uniform(0.0, 0.8), (img.shape[0], 1))  # row noise
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def motionBlur(rng, img):
    """A straight motion of 3-12 px during the exposure: the frame convolved with a line of that
    length, sampled every 1/16 px and splatted bilinearly, so that the kernel is smooth and its
    centroid is the kernel's centre (the truth is the pose at mid-exposure)."""
    length = rng.uniform(3, 12)
    ang = rng.uniform(0, math.pi)
    half = int(math.ceil(0.5 * length)) + 1
    size = 2 * half + 1
    k = np.zeros((size, size), np.float64)
    for s in np.linspace(-0.5 * length, 0.5 * length, int(16 * length) + 1):
        x, y = half + s * math.cos(ang), half + s * math.sin(ang)
        x0, y0 = int(math.floor(x)), int(math.floor(y))
        fx, fy = x - x0, y - y0
        k[y0, x0] += (1 - fx) * (1 - fy)
        k[y0, x0 + 1] += fx * (1 - fy)
        k[y0 + 1, x0] += (1 - fx) * fy
        k[y0 + 1, x0 + 1] += fx * fy
    k /= k.sum()
    return cv2.filter2D(img, -1, k, borderType=cv2.BORDER_REFLECT)


def renderFrame(rng, target, normals, cam, category):
    """One frame: (uint8 image, truth dict or None for target-free)."""
    points = np.array(target["points"], dtype=np.float64)
    faces = target["faces"]
    centre = points.mean(axis=0)
    size_mm = float(np.max(np.linalg.norm(points - centre, axis=1))) * 2.0
    img = background(rng, cam)
    blur_px = rng.uniform(0.5, 1.4)
    truth = None
    led_peak = rng.uniform(70, 240) if category != "bright" else rng.uniform(500, 2500)
    if category != "target-free":
        rmax = cam.maxNormalisedRadius()
        for _attempt in range(200):
            f = int(rng.integers(len(faces)))
            direction = randomUnitInCone(rng, normals[f], 55.0)
            # The target 40 px across, up to 60 % of the frame's shorter side.
            span_px = rng.uniform(40.0, 0.6 * min(cam.w, cam.h))
            dist = cam.spec["fx"] * size_mm / span_px
            cam_pos = centre + direction * dist
            r, t = lookAt(cam_pos, centre, rng.uniform(-180, 180))
            # Put the target off-centre: turn the camera a little.
            off = rng.uniform(-0.7, 0.7, 2) * rmax * 0.6
            turn, _ = cv2.Rodrigues(np.array([-off[1], off[0], 0.0]) * 0.8)
            r, t = turn @ r, turn @ t
            pc = points @ r.T + t
            if np.any(pc[:, 2] < 50):
                continue
            xy = pc[:, :2] / pc[:, 2:3]
            if np.max(np.linalg.norm(xy, axis=1)) > 0.95 * rmax:
                continue
            uv = cam.project(pc)
            if np.all((uv[:, 0] > 2) & (uv[:, 0] < cam.w - 3) & (uv[:, 1] > 2) & (uv[:, 1] < cam.h - 3)):
                break
        else:
            return None, None
        cam_t = -r.T @ t
        # An LED shines when one of its faces is seen within 75 degrees of its normal.
        visible = []
        emission = []
        for i in range(len(points)):
            best = -1.0
            for fi, face in enumerate(faces):
                if i in face:
                    fc = points[face].mean(axis=0)
                    view = cam_t - fc
                    best = max(best, float(np.dot(normals[fi], view / np.linalg.norm(view))))
            visible.append(best > math.cos(math.radians(75.0)))
            emission.append(max(best, 0.0) ** 0.7)
        visible = np.array(visible)
        hidden = np.zeros(len(points), bool)
        if category == "occluded":
            idx = np.flatnonzero(visible)
            hidden[rng.choice(idx, size=min(len(idx) - 1, int(rng.integers(1, 3))), replace=False)] = True
        dimmed = np.ones(len(points))
        if category == "dim":
            idx = np.flatnonzero(visible)
            for i in rng.choice(idx, size=min(len(idx), int(rng.integers(1, 3))), replace=False):
                dimmed[i] = rng.uniform(0.25, 0.4)
        z_ref = float(np.min(pc[:, 2]))
        led_radius_mm = rng.uniform(1.5, 3.5)
        drawn = 0
        for i in range(len(points)):
            if not visible[i] or hidden[i]:
                continue
            disc = cam.spec["fx"] * led_radius_mm / pc[i, 2]
            peak = led_peak * emission[i] * dimmed[i] * (z_ref / pc[i, 2]) ** 2
            drawSpot(img, uv[i, 0], uv[i, 1], peak, disc, blur_px)
            drawn |= 1 << i
        truth = {"R": r, "t": t, "range_mm": float(np.linalg.norm(t)), "drawn": drawn,
                 "led_px": [uv[i].tolist() for i in range(len(points)) if drawn & (1 << i)],
                 "leds_drawn": int(bin(drawn).count("1"))}
    n_clutter = {"clean": 0, "clutter": int(rng.integers(4, 12)), "heavy": int(rng.integers(12, 30)),
                 "target-free": int(rng.integers(0, 30))}.get(category, int(rng.integers(0, 6)))
    for _ in range(n_clutter):
        u, v = rng.uniform(0, cam.w), rng.uniform(0, cam.h)
        kind = rng.choice(["dot", "dot", "ellipse", "streak", "patch"])
        level = rng.uniform(30, 400)
        if kind == "dot":
            drawSpot(img, u, v, rng.uniform(0.2, 1.5) * led_peak, rng.uniform(0, 2.5), blur_px)
        elif kind == "ellipse":
            drawEllipse(img, rng, u, v, level)
        elif kind == "streak":
            drawStreak(img, rng, u, v, level)
        else:
            drawPatch(img, rng, u, v, rng.uniform(20, 300))
    if category == "blur":
        img = motionBlur(rng, img)
    return sensor(rng, img), truth


def writePgm(path, img):
    with open(path, "wb") as f:
        f.write(b"P5\n%d %d\n255\n" % (img.shape[1], img.shape[0]))
        f.write(img.tobytes())


def equivalents(report, syms):
    """The reported pose's equivalents under the target's symmetries (rs, ts): for each, its
    rotation and translation (R rs, R ts + t) and R ts (how far its translation moves with R)."""
    r_rep = quatToR(report["q_wxyz"])
    t_rep = np.array(report["t_mm"])
    for rs, ts in syms:
        a = r_rep @ ts
        yield r_rep @ rs, a + t_rep, a


def poseError(truth, report, syms):
    """Rotation (degrees) and translation (mm) error of a reported pose, the smallest over the
    target's symmetries (the rotation's, and the translation of that same equivalent)."""
    best = None
    for r, t, _ in equivalents(report, syms):
        cos_ang = (np.trace(r.T @ truth["R"]) - 1.0) / 2.0
        err = (math.degrees(math.acos(max(-1.0, min(1.0, cos_ang)))),
               float(np.linalg.norm(t - truth["t"])))
        if best is None or err < best:
            best = err
    return best


def rotationLog(r):
    """The rotation vector of r (radians)."""
    cos_ang = max(-1.0, min(1.0, (np.trace(r) - 1.0) / 2.0))
    ang = math.acos(cos_ang)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    if ang < 1e-9:
        return 0.5 * w
    return w * (ang / (2.0 * math.sin(ang)))


def normalisedError(truth, report, syms):
    """The reported pose's error against the truth (its nearest symmetric equivalent), as dockpose's
    covariance parametrises it -- (tx, ty, tz) mm, then the rotation r (rad) with R_true =
    exp([r]x) R -- divided by its sigmas, and its NEES e^T C^-1 e. None without a covariance."""
    if "covariance" not in report:
        return None
    cov = np.array(report["covariance"], dtype=np.float64)
    best = None
    for r, t, a in equivalents(report, syms):
        e = np.concatenate([truth["t"] - t, rotationLog(truth["R"] @ r.T)])
        # The equivalent's translation moves with the rotation: t' = R ts + t, a = R ts.
        jac = np.eye(6)
        jac[0:3, 3:6] = -np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
        c = jac @ cov @ jac.T
        if best is None or np.linalg.norm(e[3:]) < np.linalg.norm(best[0][3:]):
            best = (e, c)
    e, c = best
    try:
        nees = float(e @ np.linalg.solve(c, e))
    except np.linalg.LinAlgError:
        return None
    z = [float(e[i] / math.sqrt(c[i, i])) if c[i, i] > 0 else float("nan") for i in range(6)]
    return z, nees


def withinBar(truth, error):
    """Within 2 degrees and max(5 mm, 2 % of range) of the truth (issue 8's bar)."""
    rot_deg, t_mm = error
    return rot_deg <= 2.0 and t_mm <= max(5.0, 0.02 * truth["range_mm"])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dockpose", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--frames", type=int, default=4, help="frames per (target, camera, category)")
    ap.add_argument("--seed", type=int, default=2027)
    ap.add_argument("--out", help="keep the frames and results here")
    ap.add_argument("--max-sigma-ratio", type=float,
                    help="fail when, over the correct poses, error/sigma has a standard deviation "
                    "above this on any axis (the covariance claims more precision than it has)")
    args = ap.parse_args()

    out = args.out or tempfile.mkdtemp(prefix="dockpose_independent_")
    os.makedirs(out, exist_ok=True)
    targets = {}
    for name in ("wedge", "corner", "pyramid", "roof"):
        with open(os.path.join(args.data, name + ".json")) as f:
            targets[name] = json.load(f)
    targets["hinge"] = hingeTarget()
    cameras = {}
    for name in ("cam512", "cam1456", "cam-wide"):
        with open(os.path.join(args.data, name + ".json")) as f:
            cameras[name] = json.load(f)
    cameras.update(EXTRA_CAMERAS)

    rng = np.random.default_rng(args.seed)
    log = open(os.path.join(out, "results.jsonl"), "w")
    stats = {}
    wrong = []
    free_poses = []
    z_all, nees_all = [], []  # over the correct poses: error / sigma per axis, NEES
    for tname, target in targets.items():
        tpath = os.path.join(out, tname + ".json")
        with open(tpath, "w") as f:
            json.dump(target, f)
        points = np.array(target["points"], dtype=np.float64)
        normals = faceNormals(points, target["faces"])
        syms = symmetries(points)
        for cname, spec in cameras.items():
            cpath = os.path.join(out, cname + ".json")
            with open(cpath, "w") as f:
                json.dump(spec, f)
            cam = Camera(spec)
            frames = []
            for category in CATEGORIES:
                for k in range(args.frames):
                    img, truth = renderFrame(rng, target, normals, cam, category)
                    if img is None:
                        continue
                    path = os.path.join(out, "%s_%s_%s_%03d.pgm" % (tname, cname, category, k))
                    writePgm(path, img)
                    frames.append((path, category, truth))
            res = subprocess.run([args.dockpose, "solve", "-t", tpath, "-c", cpath] +
                                 [p for p, _, _ in frames], capture_output=True, text=True)
            if res.returncode != 0:
                print("dockpose solve failed (%d) on %s/%s: %s" % (res.returncode, tname, cname,
                                                                  res.stderr.strip()))
                return 1
            reports = {}
            for line in res.stdout.splitlines():
                j = json.loads(line)
                reports[j["image"]] = j
            for path, category, truth in frames:
                rep = reports.get(path)
                if rep is None:
                    print("no result for", path)
                    return 1
                key = (tname, category)
                error = poseError(truth, rep, syms) if truth and rep["found"] else None
                correct = error is not None and withinBar(truth, error)
                normalised = normalisedError(truth, rep, syms) if correct else None
                if normalised is not None:
                    z_all.append(normalised[0])
                    nees_all.append(normalised[1])
                log.write(json.dumps({"image": path, "category": category, "status": rep["status"],
                                      "blobs": rep.get("blobs"), "leds": rep.get("leds"),
                                      "drawn": truth["leds_drawn"] if truth else 0,
                                      "range_mm": truth["range_mm"] if truth else 0,
                                      "led_px": truth["led_px"] if truth else [],
                                      "truth_R": truth["R"].tolist() if truth else None,
                                      "truth_t": truth["t"].tolist() if truth else None,
                                      "error": error, "correct": correct,
                                      "z": normalised[0] if normalised else None,
                                      "nees": normalised[1] if normalised else None}) + "\n")
                s = stats.setdefault(key, {"frames": 0, "found": 0, "wrong": 0, "ge5": 0,
                                           "ge5_found": 0})
                s["frames"] += 1
                if truth is None:
                    if rep["found"]:
                        free_poses.append(path)
                    continue
                ge5 = truth["leds_drawn"] >= 5
                s["ge5"] += ge5
                if rep["found"]:
                    if correct:
                        s["found"] += 1
                        s["ge5_found"] += ge5
                    else:
                        s["wrong"] += 1
                        # The rotation's sigma along its worst axis (roll/pan/tilt sigmas
                        # swell near pan +-90 degrees whatever the rotation's own).
                        cov = np.array(rep["covariance"])
                        sigma_deg = math.degrees(math.sqrt(max(np.linalg.eigvalsh(cov[3:, 3:]))))
                        wrong.append((path, truth["range_mm"], error, sigma_deg, rep.get("leds"),
                                      rep.get("log10_nfa")))

    print("independent renderer: %d targets x %d cameras x %d categories x %d frames (seed %d)"
          % (len(targets), len(cameras), len(CATEGORIES), args.frames, args.seed))
    print("%-9s %-12s %7s %8s %7s %12s" % ("target", "category", "frames", "correct", "wrong",
                                         ">=5 drawn"))
    for (tname, category), s in sorted(stats.items()):
        if category == "target-free":
            print("%-9s %-12s %7d %8s %7s %12s" % (tname, category, s["frames"], "-", "-", "-"))
            continue
        print("%-9s %-12s %7d %7.0f%% %7d %6d/%-5d" % (
            tname, category, s["frames"], 100.0 * s["found"] / max(s["frames"], 1), s["wrong"],
            s["ge5_found"], s["ge5"]))
    total = sum(s["frames"] for k, s in stats.items() if k[1] != "target-free")
    found = sum(s["found"] for s in stats.values())
    ge5 = sum(s["ge5"] for s in stats.values())
    ge5_found = sum(s["ge5_found"] for s in stats.values())
    n_free = sum(s["frames"] for k, s in stats.items() if k[1] == "target-free")
    print("with the target: %d frames, %d correct (%.1f %%); >= 5 LEDs drawn: %d of %d (%.1f %%); "
          "wrong: %d" % (total, found, 100.0 * found / max(total, 1), ge5_found, ge5,
                         100.0 * ge5_found / max(ge5, 1), len(wrong)))
    print("target-free: %d frames, %d with a pose" % (n_free, len(free_poses)))
    if z_all:
        # chi^2(6)'s 95 % point: 12.592.
        z = np.array(z_all)
        nees = np.array(nees_all)
        print("correct poses: %d; std of error/sigma (tx ty tz rx ry rz): %s; NEES mean %.2f "
              "(chi2(6): 6), median %.2f (5.35), above the 95 %% point %.1f %% (5 %%)"
              % (len(nees), " ".join("%.2f" % v for v in np.nanstd(z, axis=0)), nees.mean(),
                 float(np.median(nees)), 100.0 * float(np.mean(nees > 12.592))))
    overconfident = False
    if args.max_sigma_ratio and z_all:
        worst = float(np.nanmax(np.nanstd(np.array(z_all), axis=0)))
        if worst > args.max_sigma_ratio:
            overconfident = True
            print("OVERCONFIDENT: error/sigma has a standard deviation of %.2f on an axis "
                  "(limit %.2f)" % (worst, args.max_sigma_ratio))
    for w in wrong:
        print("WRONG: %s range %.0f mm, error %.2f deg %.1f mm, rotation sigma %.2f deg (worst "
              "axis), %s LEDs, log10 NFA %s" % (w[0], w[1], w[2][0], w[2][1], w[3], w[4], w[5]))
    for p in free_poses:
        print("POSE ON A TARGET-FREE FRAME:", p)
    if not args.out:
        shutil.rmtree(out)
    return 1 if wrong or free_poses or overconfident else 0


if __name__ == "__main__":
    sys.exit(main())
