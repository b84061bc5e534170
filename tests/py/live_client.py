#!/usr/bin/env python3
"""An independent client of the Foxglove WebSocket protocol (the `websockets` package; the
protocol of github.com/foxglove/ws-protocol, whose subprotocol `foxglove.websocket.v1` the
Foxglove SDK serves under its newer name `foxglove.sdk.v1`: the client offers both and the
server picks): connects to a live server, collects the advertised channels, subscribes, and
reports as one JSON line.

    live_client.py ws://HOST:PORT --topic /pose/measured --seconds 4
    live_client.py ws://HOST:PORT --all --stall --seconds 8

Reading (default): counts the messages of the subscribed topic for SECONDS (after the first one
arrived, waiting at most 10 s for it) and reports their count, rate and the log times' span.
--stall: subscribes (to --topic or --all channels), then stops reading for SECONDS: the socket's
receive buffer and the library's queue fill up, so the server sees a viewer that does not keep up.
"""

import argparse
import asyncio
import json
import socket
import struct
import urllib.parse
import sys
import time

import websockets

# The protocol's names, oldest first; the SDK accepts only the newer one.
SUBPROTOCOLS = ["foxglove.websocket.v1", "foxglove.sdk.v1"]
OP_MESSAGE_DATA = 0x01


async def advertised(ws, settle_s=1.0):
    """Channels advertised until no advertisement came for settle_s."""
    channels = {}
    end = time.monotonic() + 10.0
    while time.monotonic() < end:
        try:
            msg = await asyncio.wait_for(ws.recv(), timeout=settle_s)
        except asyncio.TimeoutError:
            if channels:
                break
            continue
        if isinstance(msg, str):
            m = json.loads(msg)
            if m.get("op") == "advertise":
                for ch in m["channels"]:
                    channels[ch["topic"]] = ch
    return channels


def small_socket(url):
    """A TCP connection with a small receive buffer (a stalled reader fills it at once)."""
    u = urllib.parse.urlparse(url)
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect((u.hostname, u.port))
    return s


async def run(a):
    sock = small_socket(a.url) if a.stall else None
    async with websockets.connect(a.url, subprotocols=SUBPROTOCOLS, max_queue=4,
                                  max_size=None, open_timeout=10, sock=sock) as ws:
        if ws.subprotocol not in SUBPROTOCOLS:
            raise SystemExit(f"server chose subprotocol {ws.subprotocol!r}")
        channels = await advertised(ws)
        topics = list(channels) if a.all else [a.topic]
        subs = []
        for i, t in enumerate(topics):
            if t not in channels:
                raise SystemExit(f"topic {t} not advertised (advertised: {sorted(channels)})")
            subs.append({"id": i + 1, "channelId": channels[t]["id"]})
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        report = {
            "advertised": {t: {"schemaName": c.get("schemaName"), "encoding": c.get("encoding"),
                               "schemaEncoding": c.get("schemaEncoding")}
                           for t, c in channels.items()},
            "subscribed": topics,
            "subprotocol": ws.subprotocol,
        }
        if a.stall:
            # Stop reading: nothing is taken from the socket from here on.
            await asyncio.sleep(a.seconds)
            report["stalled_s"] = a.seconds
            return report
        count, first_at, times = 0, None, []
        deadline = time.monotonic() + 10.0
        while True:
            now = time.monotonic()
            end = (first_at + a.seconds) if first_at is not None else deadline
            if now >= end:
                break
            try:
                msg = await asyncio.wait_for(ws.recv(), timeout=end - now)
            except asyncio.TimeoutError:
                break
            except websockets.exceptions.ConnectionClosed:
                report["closed_by_server"] = True
                break
            if isinstance(msg, bytes) and msg and msg[0] == OP_MESSAGE_DATA:
                sub_id, log_time = struct.unpack_from("<IQ", msg, 1)
                if sub_id == 1:
                    if first_at is None:
                        first_at = time.monotonic()
                    count += 1
                    times.append(log_time)
        span = (max(times) - min(times)) * 1e-9 if len(times) > 1 else 0.0
        report.update({"count": count, "seconds": a.seconds,
                       "rate_hz": count / a.seconds, "log_time_span_s": span})
        return report


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("url")
    ap.add_argument("--topic", default="/pose/measured")
    ap.add_argument("--all", action="store_true", help="subscribe to every channel")
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--stall", action="store_true")
    a = ap.parse_args()
    report = asyncio.run(run(a))
    print(json.dumps(report), flush=True)


if __name__ == "__main__":
    sys.exit(main())
