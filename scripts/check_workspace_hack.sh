#!/usr/bin/env bash
# Every crate of the workspace depends on pcr-workspace-hack (workspace-hack/Cargo.toml, README
# "Architecture"): a crate without it resolves its own features of serde, syn and the rest, and
# a build of it (maturin, the chain binaries the tests start, the release tool) compiles most of
# the workspace again. `cargo hakari manage-deps` adds the line. Whether the crate's feature list
# is current needs cargo-hakari itself (`cargo hakari generate --diff`), which CI does not
# install: a stale list costs build time, not correctness.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo metadata --format-version 1 --no-deps --locked | python3 -c '
import json, sys
meta = json.load(sys.stdin)
hack = "pcr-workspace-hack"
members = set(meta["workspace_members"])
missing = [
    f"{p['"'"'name'"'"']} ({p['"'"'manifest_path'"'"']})"
    for p in meta["packages"]
    if p["id"] in members and p["name"] != hack
    and not any(d["name"] == hack for d in p["dependencies"])
]
if missing:
    print("check_workspace_hack: these crates do not depend on " + hack
          + " (run `cargo hakari manage-deps`):", file=sys.stderr)
    for m in missing:
        print("  " + m, file=sys.stderr)
    sys.exit(1)
print(f"check_workspace_hack: every one of the {len(members) - 1} crates depends on {hack}")
'
