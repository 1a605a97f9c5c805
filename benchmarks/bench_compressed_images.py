#!/usr/bin/env python3
"""Raw against image_transport ``compressed`` camera images: bag size and encoding speed.

Copies the first ``--frames`` frame sets of a bag twice (:func:`~hmocap_ros.io.bag_images.
compress_bag_images`): as it is, and with every camera image as JPEG at ``--quality`` on
``/<camera>/image_raw/compressed``; every other topic (rig, silhouettes, ground truth) is copied
unchanged into both. Prints the two bag sizes, the camera images' bytes alone, and the
encoding's milliseconds per image. The two bags then track and evaluate alike
(``hmocap eval mocap RAW`` against ``hmocap eval mocap COMPRESSED``), which measures what the
compression costs in joint error.

    .venv/bin/python benchmarks/bench_compressed_images.py BAG --out-dir out/compressed [--frames 100]
"""
from __future__ import annotations

import argparse
from pathlib import Path


def main(argv=None) -> int:
    from hmocap_ros.io.bag_images import compress_bag_images

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bag", type=Path, help="bag with raw camera images")
    ap.add_argument("--out-dir", type=Path, required=True, help="folder of the two copies")
    ap.add_argument("--frames", type=int, default=100, help="frame sets copied (default 100)")
    ap.add_argument("--quality", type=int, default=90, help="JPEG quality (default 90)")
    ns = ap.parse_args(argv)
    ns.out_dir.mkdir(parents=True, exist_ok=True)
    raw = ns.out_dir / f"{ns.bag.stem}_{ns.frames}_raw.mcap"
    compressed = ns.out_dir / f"{ns.bag.stem}_{ns.frames}_jpeg{ns.quality}.mcap"
    _raw_copy(ns.bag, raw, ns.frames)
    stats = compress_bag_images(ns.bag, compressed, "jpeg", ns.quality, ns.frames)
    raw_mb, jpeg_mb = raw.stat().st_size / 1e6, compressed.stat().st_size / 1e6
    print(f"{raw}: {raw_mb:.1f} MB")
    print(f"{compressed}: {jpeg_mb:.1f} MB ({raw_mb / jpeg_mb:.1f}x smaller); JPEG {ns.quality}: "
          f"{1e3 * stats.encode_seconds / max(stats.images, 1):.2f} ms per image ({stats.images} images)")
    print(f"camera images alone: {stats.raw_bytes / 1e6:.1f} MB raw, {stats.compressed_bytes / 1e6:.1f} MB JPEG "
          f"({stats.raw_bytes / max(stats.compressed_bytes, 1):.1f}x smaller)")
    return 0


def _raw_copy(source: Path, out: Path, frames: int) -> None:
    """The same messages as the compressed copy, the images raw."""
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.bag_writer import LATCHED, VOLATILE, whole_bag
    from hmocap_ros.io.msg_factory import stamp_to_ns

    with BagReader(source) as reader:
        available = reader.topics()
        first = sorted(t for t, i in available.items() if t.endswith("/image_raw"))[:1]
        stamps = sorted(stamp_to_ns(m.msg.header.stamp) for m in reader.messages(first))
        last = stamps[min(frames, len(stamps)) - 1]
        with whole_bag(out) as writer:
            for topic, info in available.items():
                writer.add_topic(topic, info.msgtype, LATCHED if info.latched else VOLATILE)
            for item in reader.messages(raw=True):
                if item.log_time_ns > last and not available[item.topic].latched:
                    break
                writer.write(item.topic, item.msg, item.log_time_ns, msgtype=item.msgtype)


if __name__ == "__main__":
    raise SystemExit(main())
