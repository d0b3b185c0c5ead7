#!/usr/bin/env bash
# The core's module import graph (from the `crate::` paths of src/, tests left out), one line
# per module: what it imports and how often. Fails when an arrow goes against the data flow.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test -q --test module_graph every_module -- --nocapture 2>&1 | grep '→'
