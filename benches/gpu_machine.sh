#!/bin/bash
# GPU figures and GPU tests on a lent machine without Rust (the `device` tool's H100/H200):
#
#   bash benches/gpu_machine.sh pack        # here: builds the GPU test binaries, the harness
#                                           # and the CLI, stripped into .devbin/bins.tar.xz
#   bash benches/gpu_machine.sh run [all|tests|bench]   # there (carry .devbin and .gl)
#
# `run` unpacks the Vulkan loader debs from .gl/ (see the device tool's README), runs every
# GPU test binary with IMPRINT_REQUIRE_GPU=1, then `harness --only $SECTIONS` (default
# gpu,render,stages_gpu), and copies the results to $OUT. The binaries find the repository
# through the path they were built at (/work/main), which is linked to the copy there.
set -u
case "${1:-}" in
pack)
    set -e
    cd "$(dirname "$0")/.."
    list=$(mktemp)
    cargo test --release --workspace --no-run --message-format=json 2>/dev/null | python3 -c '
import sys, json
for line in sys.stdin:
    try: m = json.loads(line)
    except ValueError: continue
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["profile"]["test"]:
        print(m["target"]["name"], m["executable"])' >"$list"
    cargo build --release -p imprint-benches --bin harness -p imprint-cli
    sel=$(mktemp -d)
    while read -r name path; do
        case $name in gpu_* | cloth_signed | cli | resume | frame_golden) cp "$path" "$sel/$name" ;; esac
    done <"$list"
    cp target/release/harness target/release/imprint "$sel/"
    strip "$sel"/*
    mkdir -p .devbin
    tar -C "$sel" -cJf .devbin/bins.tar.xz .
    rm -rf "$sel" "$list"
    ;;
run)
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
    icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    [ -f $icd ] && export VK_DRIVER_FILES=$icd \
        __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv
    [ "$PWD" = /work/main ] || { mkdir -p /work && ln -sfn "$PWD" /work/main; }
    mkdir -p bin target/release && tar -C bin -xJf .devbin/bins.tar.xz && cp bin/imprint target/release/
    export IMPRINT_REQUIRE_GPU=1 XDG_RUNTIME_DIR=/tmp
    mode=${2:-all}
    if [ "$mode" != bench ]; then
        bin/gpu_arith --nocapture 2>&1 | grep quotients
        for t in bin/gpu_* bin/cloth_signed bin/frame_golden bin/cli bin/resume; do
            echo "== $t"
            timeout 200 "$t" --test-threads 8 2>&1 | grep -v "^test .* ok$" | tail -25
        done 2>&1 | tee "$OUT/tests.log"
    fi
    if [ "$mode" != tests ]; then
        s=${SECTIONS:-gpu,render,stages_gpu}
        timeout 250 bin/harness --only "$s" --repeat 15 2>&1 | tail -20
        for x in ${s//,/ }; do cp "benches/results/$x.md" "$OUT/"; done
    fi
    ;;
*)
    sed -n 2,12p "$0"
    exit 2
    ;;
esac
