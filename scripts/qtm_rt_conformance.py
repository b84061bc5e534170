"""Conformance of the project's QTM simulator with the official Qualisys Python SDK (qtm-rt).

Starts `pcr qtm serve` (the simulated plant, capture without noise, dropouts or latency, and
its true state logged per cycle), connects with qtm_rt (asyncio), negotiates the protocol
version, reads the parameters, streams 6DOF Euler and 3D frames (with and without residuals,
all frames and Frequency:n) and compares every frame that has a truth row with the plant's
truth (capture frame). Exit status 0 when everything agrees.
"""

import argparse
import asyncio
import csv
import importlib.metadata
import math
import os
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

import qtm_rt
from qtm_rt.packet import QRTComponentType

TOL_MM = 2e-3  # float32 on the wire: ~3e-5 mm at 300 mm; generous
TOL_DEG = 1e-3
LABELS = ["B1", "B2", "B3", "M1", "M2", "M3"]


def fail(msg):
    print(f"qtm-rt conformance: FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


async def collect(conn, components, frames, n):
    packets = []
    done = asyncio.get_running_loop().create_future()

    def on_packet(p):
        packets.append(p)
        if len(packets) >= n and not done.done():
            done.set_result(None)

    await conn.stream_frames(frames=frames, components=components, on_packet=on_packet)
    await asyncio.wait_for(done, timeout=20)
    await conn.stream_frames_stop()
    await asyncio.sleep(0.2)
    return packets


async def run(port):
    bad = await qtm_rt.connect("127.0.0.1", port=port, version="1.99")
    if bad is not None:
        fail("version 1.99 was accepted")
    conn = await qtm_rt.connect("127.0.0.1", port=port, version="1.25")
    if conn is None:
        fail("cannot connect with version 1.25")
    order = (await conn.byte_order()).decode()
    if "little" not in order:
        fail(f"byte order: {order}")
    xml = await conn.get_parameters(parameters=["general", "3d", "6d"])
    root = ET.fromstring(xml)
    if root.tag != "QTM_Parameters_Ver_1.25":
        fail(f"XML root {root.tag}")
    freq = float(root.find("General/Frequency").text)
    labels = [e.text for e in root.findall("The_3D/Label/Name")]
    bodies = [e.text for e in root.findall("The_6D/Body/Name")]
    if freq != 100.0 or labels != LABELS or bodies != ["platform"]:
        fail(f"parameters: {freq} {labels} {bodies}")
    res = await collect(conn, ["6deulerres", "3dres"], "allframes", 150)
    plain = await collect(conn, ["6deuler", "3d"], "frequency:10", 5)
    conn.disconnect()
    return res, plain


def check(packets, truth, residuals):
    compared = 0
    last = None
    for p in packets:
        if last is not None and p.framenumber <= last:
            fail(f"frame numbers not increasing: {last} then {p.framenumber}")
        last = p.framenumber
        if residuals:
            _, bodies = p.get_6d_euler_residual()
            _, markers = p.get_3d_markers_residual()
        else:
            _, bodies = p.get_6d_euler()
            _, markers = p.get_3d_markers()
        if len(bodies) != 1 or len(markers) != 6:
            fail(f"frame {p.framenumber}: {len(bodies)} bodies, {len(markers)} markers")
        row = truth.get(p.framenumber)
        if row is None:
            continue
        if int(row["timestamp_us"]) != p.timestamp:
            fail(f"frame {p.framenumber}: timestamp {p.timestamp} != {row['timestamp_us']}")
        pos, euler = bodies[0][0], bodies[0][1]
        dx = max(abs(pos.x - float(row["x_mm"])), abs(pos.y - float(row["y_mm"])), abs(pos.z))
        da = max(abs(euler.a1), abs(euler.a2), abs(euler.a3 - float(row["phi_deg"])))
        if dx > TOL_MM or da > TOL_DEG:
            fail(f"frame {p.framenumber}: body {pos} {euler} vs truth {row}")
        for k, label in enumerate(LABELS):
            m = markers[k]
            if any(math.isnan(v) for v in (m.x, m.y, m.z)):
                fail(f"frame {p.framenumber}: marker {label} not measured")
            d = max(abs(m.x - float(row[f"{label}_x_mm"])),
                    abs(m.y - float(row[f"{label}_y_mm"])), abs(m.z))
            if d > TOL_MM:
                fail(f"frame {p.framenumber}: marker {label} off by {d} mm")
        compared += 1
    return compared


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pcr", required=True, help="the pcr binary")
    ap.add_argument("--workdir", required=True)
    a = ap.parse_args()
    truth_path = os.path.join(a.workdir, "truth.csv")
    srv = subprocess.Popen(
        [a.pcr, "qtm", "serve", "--port", "0", "--ideal-capture", "--truth", truth_path,
         "--seconds", "60"],
        stdout=subprocess.PIPE, text=True)
    try:
        line = srv.stdout.readline()
        if not line.startswith("listening on "):
            fail(f"simulator did not start: {line!r}")
        port = int(line.rsplit(":", 1)[1])
        t0 = time.time()
        res, plain = asyncio.run(run(port))
        time.sleep(0.2)
        with open(truth_path) as f:
            truth = {int(r["frame"]): r for r in csv.DictReader(f)}
        n1 = check(res, truth, True)
        n2 = check(plain, truth, False)
        steps = [b.framenumber - a.framenumber for a, b in zip(plain, plain[1:])]
        if any(s != 10 for s in steps):
            fail(f"Frequency:10 at 100 Hz should give every 10th frame: {steps}")
        if n1 < 50 or n2 < 2:
            fail(f"too few frames compared with the truth: {n1}, {n2}")
        print(f"qtm-rt {importlib.metadata.version('qtm-rt')} conformance: "
              f"OK: version 1.25 negotiated (1.99 refused), parameters, {len(res)} 6DEulerRes+3DRes "
              f"frames ({n1} compared with the plant's truth), {len(plain)} 6DEuler+3D frames at "
              f"Frequency:10 ({n2} compared), {time.time() - t0:.1f} s")
    finally:
        srv.terminate()
        srv.wait(timeout=10)


if __name__ == "__main__":
    main()
