#!/usr/bin/env bash
# The ESI corpus tried as a new user would: for every device type of every file in
# ESI_CORPUS (default ../shared/esi-corpus), `ferrocat run --device EK1100 --device FILE:TYPE
# --dc --seconds 0.2 --json` on the embedded virtual segment (the type's device as FILE:TYPE
# picks it, modular ones with their default modules). Prints, per file, the types that reached
# OP with process data, and each failure's first error line; last, the totals. Not in CI: it
# reads every vendor file there is (a few minutes).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build -q --release -p ferrocat
corpus="${ESI_CORPUS:-../shared/esi-corpus}"
[ -d "$corpus" ] || { echo "no corpus at $corpus (set ESI_CORPUS)"; exit 1; }
python3 - "$corpus" target/release/ferrocat <<'PY'
import json, subprocess, sys, os, collections
corpus, bin = sys.argv[1], sys.argv[2]
total = collections.Counter()
for name in sorted(os.listdir(corpus)):
    if not name.lower().endswith(".xml"):
        continue
    path = os.path.join(corpus, name)
    r = subprocess.run([bin, "esi", path, "--json"], capture_output=True, text=True)
    if r.returncode != 0:
        print(f"{name}: refused: {r.stderr.strip().splitlines()[-1]}")
        total["files refused"] += 1
        continue
    info = json.loads(r.stdout)
    # By type name; a device without one (IgH's dump) by its product code.
    types = list(dict.fromkeys(d["type"] or f"#x{d['product_code']:x}" for d in info["devices"]))
    passive = len(info.get("passive", []))
    ok, failed = 0, []
    for t in types:
        try:
            run = subprocess.run([bin, "run", "--device", "EK1100", "--device", f"{path}:{t}", "--dc",
                                  "--seconds", "0.2", "--json", "--no-control"],
                                 capture_output=True, text=True, timeout=60)
        except subprocess.TimeoutExpired:
            failed.append((t, "no result within 60 s"))
            continue
        good, why = False, None
        if run.returncode == 0:
            try:
                v = json.loads(run.stdout)
                s = v.get("slaves", {})
                good = s.get("in_op_at_end") == s.get("count") and v.get("wkc_errors", 1) == 0
                if not good:
                    left = [l for l in run.stderr.splitlines() if "left OP" in l or "AL status" in l]
                    why = (f"in OP at the end: {s.get('in_op_at_end')} of {s.get('count')}, "
                           f"{v.get('wkc_errors')} working-counter errors" + (f"; {left[0].strip()[:120]}" if left else ""))
            except json.JSONDecodeError:
                pass
        if good:
            ok += 1
        elif why:
            failed.append((t, why))
        else:
            lines = [l for l in run.stderr.splitlines() if "error" in l] or run.stderr.splitlines()[-1:] or ["no output"]
            failed.append((t, lines[0].replace("ferrocat: error: ", "")[:160]))
    total["types"] += len(types)
    total["reached OP"] += ok
    total["passive"] += passive
    print(f"{name}: {ok} of {len(types)} types reached OP" + (f"; {passive} passive (no ESC)" if passive else ""))
    for t, why in failed:
        print(f"    {t}: {why}")
print(f"total: {total['reached OP']} of {total['types']} types reached OP; {total['passive']} passive; {total['files refused']} files refused")
PY
