"""A Groot2-protocol client's view of one agent's tree, drawn from what `swarmbed groot` answers.

Groot2 itself cannot run on the machine these docs were made on, so this script asks the gateway
what Groot2 asks (the tree, ``T``; the status buffer, ``S``; the main tree's blackboard, ``B``)
over the same ZeroMQ request socket, and draws the answer: SubTree instances expanded in place,
each node coloured by its status as Groot2 colours it (a node back to IDLE in a pale shade of the
status it left), the blackboard beside it.

    swarmbed groot --connect EP --credentials me.cred --agent 3 &
    python docs/scripts/groot_view.py --port 1667 --out docs/images/groot_view.png
"""

from __future__ import annotations

import argparse
import struct
from xml.etree import ElementTree

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import msgpack
import zmq

COLOURS = {0: "#d9d9d9", 1: "#f5a623", 2: "#4caf50", 3: "#e53935"}  # IDLE, RUNNING, SUCCESS, FAILURE
PALE = {1: "#fbe3bd", 2: "#cde8ce", 3: "#f6c4c3"}  # back to IDLE from that status


def ask(socket: zmq.Socket, kind: str, payload: bytes | None = None) -> list[bytes]:
    socket.send_multipart([struct.pack("<BBI", 2, ord(kind), 1)] + ([payload] if payload is not None else []))
    return socket.recv_multipart()[1:]


def layout(xml: str) -> tuple[list[tuple[int, str, float, int]], list[tuple[int, int]], str]:
    """Nodes (uid, label, x, depth) and edges of the main tree with SubTrees expanded, and its ID."""
    root = ElementTree.fromstring(xml)
    trees = {t.get("_fullpath", ""): t for t in root.findall("BehaviorTree")}
    main = trees[""]
    nodes: list[tuple[int, str, float, int]] = []
    edges: list[tuple[int, int]] = []
    next_x = [0.0]

    def place(el: ElementTree.Element, depth: int) -> float:
        uid = int(el.get("_uid", "0"))
        children = list(el)
        if el.tag == "SubTree":
            children = list(trees[el.get("_fullpath", "")])
            label = f"SubTree\n{el.get('_fullpath')}"
        else:
            label = el.tag if el.get("name") in (None, el.tag) else f"{el.tag}\n{el.get('name')}"
        xs = []
        for child in children:
            edges.append((uid, int(child.get("_uid", "0"))))
            xs.append(place(child, depth + 1))
        if xs:
            x = sum(xs) / len(xs)
        else:
            x, next_x[0] = next_x[0], next_x[0] + 1
        nodes.append((uid, label, x, depth))
        return x

    place(main[0], 0)
    return nodes, edges, main.get("ID", "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--port", type=int, default=1667)
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    context = zmq.Context()
    socket = context.socket(zmq.REQ)
    socket.setsockopt(zmq.RCVTIMEO, 5000)
    socket.connect(f"tcp://{args.host}:{args.port}")
    xml = ask(socket, "T")[0].decode()
    buffer = ask(socket, "S")[0]
    status = dict(struct.unpack_from("<HB", buffer, i) for i in range(0, len(buffer), 3))
    nodes, edges, main_id = layout(xml)
    board = (msgpack.unpackb(ask(socket, "B", main_id.encode())[0]) or {}).get(main_id) or {}
    socket.close()
    context.term()

    where = {uid: (x, -depth) for uid, _label, x, depth in nodes}
    width = max(x for _, _, x, _ in nodes) + 1
    fig, (tree_ax, board_ax) = plt.subplots(
        1, 2, figsize=(max(8.0, 0.95 * width) + 3, 5), gridspec_kw={"width_ratios": [max(8.0, 0.95 * width), 3]}
    )
    for parent, child in edges:
        (x0, y0), (x1, y1) = where[parent], where[child]
        tree_ax.plot([x0, x1], [y0, y1], color="#888888", linewidth=1, zorder=1)
    for uid, label, x, depth in nodes:
        code = status.get(uid, 0)
        face = PALE[code - 10] if code >= 10 else COLOURS[code]
        tree_ax.text(
            x,
            -depth,
            label,
            ha="center",
            va="center",
            fontsize=7,
            zorder=2,
            bbox={"boxstyle": "round,pad=0.3", "facecolor": face, "edgecolor": "#444444"},
        )
    tree_ax.set_xlim(-0.8, width - 0.2)
    tree_ax.set_ylim(-max(d for *_, d in nodes) - 0.6, 0.6)
    tree_ax.axis("off")
    tree_ax.set_title(
        f"{main_id}: node statuses as Groot2 gets them (S): orange running, green success, red failure, "
        "grey idle; pale: back to idle from that status",
        fontsize=9,
    )
    lines = [f"{k} = {v!r}"[:60] for k, v in sorted(board.items())]
    board_ax.text(0, 1, "\n".join(lines) or "(empty)", va="top", family="monospace", fontsize=7)
    board_ax.axis("off")
    board_ax.set_title(f"blackboard {main_id} (B)", fontsize=9)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)


if __name__ == "__main__":
    main()
