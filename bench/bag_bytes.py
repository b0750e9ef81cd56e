"""Benchmark: what a recording costs per topic, the bytes of its messages (MCAP, read with mcap's reader)
per hour of recorded time; the demo's bag by default, to size the path topics (docs/demo.md).

Usage: python -P bench/bag_bytes.py BAG [--top 12]
    BAG: a rosbag2 directory (its .mcap files) or one .mcap file, e.g. out/latest/run after
    ``./dev.sh run --duration 60``.
Prints one markdown row per topic, largest first: messages, bytes, bytes per hour and share of the total.
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

from mcap.reader import make_reader

HOUR_NS = 3600 * 10**9


def topic_bytes(bag: Path) -> tuple[Counter[str], Counter[str], int]:
    """Message bytes and counts by topic, and the span of the log times (ns), over every MCAP file."""
    sizes: Counter[str] = Counter()
    counts: Counter[str] = Counter()
    first = last = None
    for path in sorted(bag.glob("*.mcap")) if bag.is_dir() else [bag]:
        with path.open("rb") as stream:
            for _, channel, message in make_reader(stream).iter_messages():
                sizes[channel.topic] += len(message.data)
                counts[channel.topic] += 1
                first = message.log_time if first is None else min(first, message.log_time)
                last = message.log_time if last is None else max(last, message.log_time)
    if first is None:
        raise SystemExit(f"error: {bag} holds no message")
    return sizes, counts, last - first


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bag", type=Path)
    parser.add_argument("--top", type=int, default=12, help="topics listed (the rest summed in one row)")
    args = parser.parse_args()
    sizes, counts, span_ns = topic_bytes(args.bag)
    total = sum(sizes.values())
    per_hour = HOUR_NS / span_ns
    print(f"{args.bag}: {span_ns / 1e9:.1f} s recorded, {total / 1e6:.2f} MB of messages\n")
    print("| topic | messages | MB | MB per hour | share |\n|---|---|---|---|---|")
    ranked = sizes.most_common()
    rest = ranked[args.top :]
    for topic, size in ranked[: args.top]:
        hourly = size * per_hour / 1e6
        print(f"| `{topic}` | {counts[topic]} | {size / 1e6:.3f} | {hourly:.1f} | {size / total:.1%} |")
    if rest:
        size = sum(s for _, s in rest)
        print(f"| {len(rest)} others | {sum(counts[t] for t, _ in rest)} | {size / 1e6:.3f} | "
              f"{size * per_hour / 1e6:.1f} | {size / total:.1%} |")  # fmt: skip
    print(f"| total | {sum(counts.values())} | {total / 1e6:.3f} | {total * per_hour / 1e6:.1f} | 100 % |")


if __name__ == "__main__":
    main()
