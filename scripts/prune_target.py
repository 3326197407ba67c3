#!/usr/bin/env python3
"""Deletes superseded test and example executables from a cargo target folder.

A target folder kept between runs (CI's, a developer's) gains a new executable for every test
binary whose code or dependencies changed, each hundreds of megabytes with debug info, and
cargo never deletes the old ones: on 28 November one such folder had grown to 68 GB and filled
the disk mid-build. For each executable name (the part before cargo's hash) this keeps the
newest KEEP (default 2: a test built with two feature sets has two current binaries of one
name) and deletes the rest with their `.d` files. Nothing else is touched; cargo rebuilds
anything deleted that is still wanted.

usage: scripts/prune_target.py TARGET_DIR [KEEP]
"""
import collections
import os
import sys


def prune(folder, keep):
    groups = collections.defaultdict(list)
    for name in os.listdir(folder):
        path = os.path.join(folder, name)
        if "." in name or not os.path.isfile(path) or not os.access(path, os.X_OK):
            continue
        stem, _, _ = name.rpartition("-")
        if stem:
            groups[stem].append((os.path.getmtime(path), path))
    freed = 0
    for files in groups.values():
        files.sort(reverse=True)
        for _, path in files[keep:]:
            freed += os.path.getsize(path)
            os.remove(path)
            if os.path.exists(path + ".d"):
                os.remove(path + ".d")
    return freed


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__.strip().splitlines()[-1])
    target = sys.argv[1]
    keep = int(sys.argv[2]) if len(sys.argv) == 3 else 2
    freed = 0
    for profile in ("debug", "release"):
        for sub in ("deps", "examples"):
            folder = os.path.join(target, profile, sub)
            if os.path.isdir(folder):
                freed += prune(folder, keep)
    print(f"prune_target: {freed / 1e9:.1f} GB of superseded executables deleted from {target}")


if __name__ == "__main__":
    main()
