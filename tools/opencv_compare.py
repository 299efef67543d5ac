#!/usr/bin/env python3
"""Register Umbra's exported TRN frames with OpenCV SIFT and ORB, for a side-by-side with nav-core.

Each case folder (from `ground-sim trn --export DIR`) holds frame_slope.png and
reference_slope.png (16-bit grey, degrees x 512, 65535 = no data) and truth.json (the true
frame -> reference affine). For each detector: detect and describe on 8-bit slope images
(0..40 degrees -> 0..255), brute-force matching with Lowe's ratio test (0.8), a RANSAC
similarity (cv2.estimateAffinePartial2D, 3 reference px), and the same error measures as
`ground-sim trn`. Prints and writes JSON: one record per case and method.

Usage: opencv_compare.py OUT.json CASE_DIR [CASE_DIR ...]
"""
import json
import math
import sys
import time

import cv2
import numpy as np


def load(path):
    raw = cv2.imread(path, cv2.IMREAD_UNCHANGED).astype(np.float32)
    deg = np.where(raw > 90 * 512, 0.0, raw / 512.0)
    return np.clip(deg * (255.0 / 40.0), 0, 255).astype(np.uint8)


def run(case, name, frame, ref, truth):
    if name == "SIFT":
        det, norm = cv2.SIFT_create(), cv2.NORM_L2
    else:
        det, norm = cv2.ORB_create(nfeatures=2000), cv2.NORM_HAMMING
    t0 = time.perf_counter()
    kf, df = det.detectAndCompute(frame, None)
    kr, dr = det.detectAndCompute(ref, None)
    out = {"case": case, "method": name, "frame_features": len(kf), "reference_features": len(kr)}
    good = []
    if df is not None and dr is not None and len(kf) >= 2 and len(kr) >= 2:
        for m in cv2.BFMatcher(norm).knnMatch(df, dr, k=2):
            if len(m) == 2 and m[0].distance < 0.8 * m[1].distance:
                good.append(m[0])
    out["matches"] = len(good)
    model, inl = (None, None)
    if len(good) >= 3:
        src = np.float32([kf[m.queryIdx].pt for m in good])
        dst = np.float32([kr[m.trainIdx].pt for m in good])
        model, inl = cv2.estimateAffinePartial2D(src, dst, method=cv2.RANSAC, ransacReprojThreshold=3.0)
    out["time_ms"] = (time.perf_counter() - t0) * 1e3
    if model is None:
        out["fix"] = False
        return out
    a = np.asarray(truth["affine"], dtype=np.float64).reshape(2, 3)
    out["fix"] = True
    out["inliers"] = int(inl.sum())
    rot = math.degrees(math.atan2(model[1, 0], model[0, 0]))
    out["rotation_deg"] = rot
    out["heading_err_deg"] = (rot - truth["heading_deg"] + 180.0) % 360.0 - 180.0
    out["scale"] = math.hypot(model[0, 0], model[1, 0])
    c = np.array([(truth["frame_width"] - 1) / 2, (truth["frame_height"] - 1) / 2, 1.0])
    out["center_err_px"] = float(np.linalg.norm(model @ c - a @ c))
    pts = np.float32([kf[m.queryIdx].pt for m, ok in zip(good, inl.ravel()) if ok])
    ph = np.hstack([pts, np.ones((len(pts), 1))])
    err = np.linalg.norm(ph @ model.T - ph @ a.T, axis=1)
    out["pos_err_mean_px"] = float(err.mean())
    out["pos_err_max_px"] = float(err.max())
    # OpenCV's keypoint convention puts the first pixel's centre at (0, 0) like Umbra's.
    return out


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    rows = []
    for case in sys.argv[2:]:
        truth = json.load(open(f"{case}/truth.json"))
        frame, ref = load(f"{case}/frame_slope.png"), load(f"{case}/reference_slope.png")
        for name in ("SIFT", "ORB"):
            r = run(case, name, frame, ref, truth)
            rows.append(r)
            print(json.dumps(r))
    json.dump({"opencv": cv2.__version__, "results": rows}, open(sys.argv[1], "w"), indent=2)


if __name__ == "__main__":
    main()
