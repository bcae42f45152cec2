"""Does a session of our eclipse-zenoh talk to one of the Zenoh version rmw_zenoh vendors? Runs one
side here and the other under another Python (a venv with that eclipse-zenoh), both directions: the
other side as the router a ROS 2 machine's node would connect to, and as a client of a router of ours
(our hub's place). Each side puts a sample with an rmw_zenoh attachment and declares a liveliness
token under ``@ros2_lv``; the check is that each receives the other's sample, attachment and token.

    python docs/scripts/zenoh_interop.py --other /tmp/venv_z1.6.2/bin/python
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import time

SIDE = r"""
import json, sys, time, zenoh
mode, endpoint, name, peer = sys.argv[1:5]
conf = zenoh.Config()
conf.insert_json5("mode", json.dumps(mode))
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("listen/endpoints" if mode == "router" else "connect/endpoints", json.dumps([endpoint]))
got = {"sample": None, "attachment": None, "token": None}
with zenoh.open(conf) as s:
    def on_sample(x):
        attachment = x.attachment.to_bytes().hex() if x.attachment else None
        got.update(sample=x.payload.to_bytes().decode(), attachment=attachment)
    def on_token(x):
        got.update(token=str(x.key_expr))
    sub = s.declare_subscriber(f"0/interop/{peer}/**", on_sample)
    lv = s.liveliness().declare_subscriber(f"@ros2_lv/0/{peer}/**", on_token, history=True)
    token = s.liveliness().declare_token(f"@ros2_lv/0/{name}/0/0/NN/%/%/interop")
    time.sleep(2.0)
    attachment = bytes.fromhex("0100000000000000" "0200000000000000" "10") + bytes(range(16))
    key = f"0/interop/{name}/std_msgs::msg::dds_::String_/RIHS01_x"
    s.put(key, f"from {name}".encode(), attachment=attachment)
    time.sleep(2.0)
    print(json.dumps({"version": getattr(zenoh, "__version__", "?"), **got}), flush=True)
"""


def free_endpoint() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def pair(router_python: str, client_python: str) -> tuple[dict, dict]:
    endpoint = free_endpoint()
    router = subprocess.Popen(
        [router_python, "-c", SIDE, "router", endpoint, "r", "c"], stdout=subprocess.PIPE, text=True
    )
    time.sleep(1.0)
    client = subprocess.Popen(
        [client_python, "-c", SIDE, "client", endpoint, "c", "r"], stdout=subprocess.PIPE, text=True
    )
    out_c, _ = client.communicate(timeout=30)
    out_r, _ = router.communicate(timeout=30)
    return json.loads(out_r), json.loads(out_c)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--other", required=True, help="a python whose eclipse-zenoh is the other version")
    args = ap.parse_args()
    version = subprocess.run(
        [args.other, "-c", "import importlib.metadata as m; print(m.version('eclipse-zenoh'))"],
        capture_output=True,
        text=True,
    ).stdout.strip()
    ours = subprocess.run(
        [sys.executable, "-c", "import importlib.metadata as m; print(m.version('eclipse-zenoh'))"],
        capture_output=True,
        text=True,
    ).stdout.strip()
    ok = True
    for label, router, client in (
        ("their router, our client", args.other, sys.executable),
        ("our router, their client", sys.executable, args.other),
    ):
        r, c = pair(router, client)
        fine = all((r["sample"], r["attachment"], r["token"], c["sample"], c["attachment"], c["token"]))
        same = r["attachment"] == c["attachment"]
        ok &= fine and same
        verdict = "yes" if fine and same else "NO"
        print(f"{label} (ours {ours}, theirs {version}): samples, attachments and tokens both ways: {verdict}")
        if not fine:
            print("  router saw", r, "\n  client saw", c)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
