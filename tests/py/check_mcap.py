#!/usr/bin/env python3
"""Checks an MCAP written by pcr (supervisor or `pcr convert`) against its CSV recording with an
independent reader (the `mcap` Python package): the channels and their schemas, one message per
CSV row on the row channel (and per row on the pose, transform, driver and scene channels), and
every cell of the CSV equal to the row channel's value.

    check_mcap.py REC.mcap REC.csv [--scene] [--process NAME ...] [--killed]

--killed: the writer was killed: the file has no summary; the complete records are read in order
(as `mcap recover` does) and the rows found must be the CSV's first rows, reaching to within 1 s
of the CSV's last row. Prints one summary line; exits 1 naming the first thing that is wrong.
"""

import argparse
import csv
import json
import sys

from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader

KNOWN = ["t_s", "q1", "q2", "q3", "x_mm", "y_mm", "phi_deg", "m1x_mm", "m1y_mm", "m2x_mm",
         "m2y_mm", "m3x_mm", "m3y_mm", "xp_mm", "yp_mm", "phip_deg", "pose_id", "rep", "settled",
         "set"]
INTS = {"q1", "q2", "q3", "pose_id", "rep", "settled"}

# topic -> (schema name, schema encoding, message encoding)
ROW_CHANNELS = {
    "/recording/row": ("pcr.RecordingRow", "jsonschema", "json"),
    "/pose/planned": ("foxglove.PoseInFrame", "protobuf", "protobuf"),
    "/pose/measured": ("foxglove.PoseInFrame", "protobuf", "protobuf"),
    "/tf": ("foxglove.FrameTransforms", "protobuf", "protobuf"),
    "/driver/state": ("pcr.DriverState", "jsonschema", "json"),
}
SCENE = ("/robot", ("foxglove.SceneUpdate", "protobuf", "protobuf"))


def fail(msg):
    print(f"check_mcap: FAIL: {msg}")
    sys.exit(1)


def read_csv(path):
    with open(path, newline="") as f:
        lines = [l for l in f if not l.startswith("#")]
    rows = list(csv.DictReader(lines))
    if not rows:
        fail(f"{path}: no rows")
    return rows


def read_complete(path):
    """Schemas, channels and messages of a finished file (through its summary)."""
    with open(path, "rb") as f:
        r = make_reader(f)
        summary = r.get_summary()
        if summary is None:
            fail(f"{path}: no summary section (the file was not finished)")
        channels = dict(summary.channels)
        schemas = dict(summary.schemas)
        msgs = [(ch.topic, m) for _, ch, m in r.iter_messages(log_time_order=False)]
    return schemas, channels, msgs


def read_recovered(path):
    """The complete records of a file whose writer was killed, in order, up to the first torn one."""
    schemas, channels, msgs = {}, {}, []
    torn = None
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f, skip_magic=False).records:
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    channels[rec.id] = rec
                elif isinstance(rec, Message):
                    msgs.append((channels[rec.channel_id].topic, rec))
        except Exception as e:  # the torn tail of a killed writer
            torn = f"{type(e).__name__}: {e}"
    return schemas, channels, msgs, torn


def cell_value(col, text):
    if text == "":
        return None
    if col in INTS:
        return int(text)
    if col == "set":
        return text
    return float(text)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mcap")
    ap.add_argument("csv")
    ap.add_argument("--scene", action="store_true", help="the robot is drawn on /robot")
    ap.add_argument("--process", action="append", default=[],
                    help="a process whose cycle statistics must be on /process/NAME/stats")
    ap.add_argument("--killed", action="store_true")
    a = ap.parse_args()

    rows = read_csv(a.csv)
    if a.killed:
        schemas, channels, msgs, torn = read_recovered(a.mcap)
    else:
        schemas, channels, msgs = read_complete(a.mcap)
        torn = None

    counts = {}
    for topic, _ in msgs:
        counts[topic] = counts.get(topic, 0) + 1
    n_row = counts.get("/recording/row", 0)

    if a.killed:
        if n_row == 0:
            fail("no row recovered")
        if n_row > len(rows):
            fail(f"{n_row} rows recovered, but the CSV has only {len(rows)}")
        ref = rows[:n_row]
        last_mcap = float(rows[n_row - 1]["t_s"])
        last_csv = float(rows[-1]["t_s"])
        if last_csv - last_mcap > 1.0:
            fail(f"the recovered rows end at t = {last_mcap:.3f} s, the CSV at {last_csv:.3f} s "
                 "(more than 1 s lost)")
    else:
        ref = rows
        if n_row != len(rows):
            fail(f"/recording/row: {n_row} messages for {len(rows)} CSV rows")

    def complete(r, cols):
        return all(r.get(c, "") != "" for c in cols)

    want = {
        "/pose/planned": sum(complete(r, ["xp_mm", "yp_mm", "phip_deg"]) for r in ref),
        "/pose/measured": sum(complete(r, ["x_mm", "y_mm", "phi_deg"]) for r in ref),
        "/tf": len(ref),
        "/driver/state": len(ref),
    }
    if a.scene:
        want["/robot"] = len(ref)
    expected = dict(ROW_CHANNELS)
    if a.scene:
        expected[SCENE[0]] = SCENE[1]
    for p in a.process:
        expected[f"/process/{p}/stats"] = ("pcr.CycleStats", "jsonschema", "json")
    by_topic = {ch.topic: ch for ch in channels.values()}
    for topic, (sname, senc, menc) in expected.items():
        ch = by_topic.get(topic)
        if ch is None and want.get(topic, 1) == 0:
            continue  # no row has it: no message, no channel
        if ch is None:
            fail(f"no channel {topic} (channels: {sorted(by_topic)})")
        s = schemas.get(ch.schema_id)
        if s is None or s.name != sname or s.encoding != senc or ch.message_encoding != menc:
            got = (s.name, s.encoding) if s else None
            fail(f"{topic}: schema {got} / {ch.message_encoding}, expected {sname} {senc} / {menc}")
        if senc == "jsonschema":
            json.loads(s.data)

    for topic, n in want.items():
        got = counts.get(topic, 0)
        # A killed writer may have written a row's first channels but not the rest.
        if (got != n) if not a.killed else (abs(got - n) > 1):
            fail(f"{topic}: {got} messages, expected {n} (one per row that has it)")

    row_msgs = [json.loads(m.data) for t, m in msgs if t == "/recording/row"]
    row_msgs.sort(key=lambda v: v["t_s"])
    header = list(rows[0].keys())
    for i, (r, v) in enumerate(zip(ref, row_msgs)):
        for col in header:
            c = cell_value(col, r[col]) if col in KNOWN else (r[col] or None)
            if v.get(col, "<missing>") != c:
                fail(f"row {i}, column {col}: CSV {r[col]!r}, MCAP {v.get(col, '<missing>')!r}")
    for p in a.process:
        if counts.get(f"/process/{p}/stats", 0) == 0:
            fail(f"no cycle statistics of {p}")

    print(f"check_mcap: OK: {a.mcap}: {n_row} rows of {len(rows)} in the CSV, "
          f"{len(by_topic)} channels, {len(msgs)} messages"
          + (f"; recovered up to a torn tail ({torn})" if torn else "")
          + "; counts " + json.dumps(dict(sorted(counts.items()))))


if __name__ == "__main__":
    main()
