"""Compare every <task>/results.json under two output roots, timing fields aside.

usage: python tools/compare_results.py ROOT_A ROOT_B [--all]   (e.g. the outputs/paper of two checkouts)
Prints, per task, the number of differences, the largest relative difference of the numbers that differ and
how many differences are not numbers (a verdict, a check, a string: what round-off cannot explain), then the
first 40 differing paths (every one with --all); exit 1 when any differ. Timing fields: keys matching TIMING.
"""
import json, re, sys
from pathlib import Path

TIMING = re.compile(r"(^created$|time|seconds|wall|elapsed|duration|_ms$|_ms_|ms_per|us_per|_s$|per_step|speed|real_time|x_real)", re.I)

def walk(a, b, path, out, pairs):
    """Append each differing path to ``out`` and each differing leaf pair (a, b) to ``pairs``."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if TIMING.search(str(k)):
                continue
            if k not in a or k not in b:
                out.append(f"{path}/{k}: only in {'B' if k not in a else 'A'}")
            else:
                walk(a[k], b[k], f"{path}/{k}", out, pairs)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{path}: length {len(a)} vs {len(b)}")
        for i, (x, y) in enumerate(zip(a, b)):
            walk(x, y, f"{path}[{i}]", out, pairs)
    elif a != b:
        out.append(f"{path}: {a!r} vs {b!r}")
        pairs.append((a, b))

def _number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def summary(pairs):
    """``largest relative difference of the numbers, count of the other differences`` of (a, b) pairs."""
    rel = [abs(a - b) / max(abs(a), abs(b)) for a, b in pairs if _number(a) and _number(b)]
    return (max(rel) if rel else 0.0), sum(not (_number(a) and _number(b)) for a, b in pairs)


ra, rb = map(Path, sys.argv[1:3])
show = None if "--all" in sys.argv[3:] else 40
bad = 0
for fa in sorted(ra.glob("*/results.json")):
    fb = rb / fa.parent.name / "results.json"
    if not fb.exists():
        print(f"{fa.parent.name}: missing in B"); bad += 1; continue
    out, pairs = [], []
    da, db = json.loads(fa.read_text()), json.loads(fb.read_text())
    for d in (da, db):  # Q6's headline is a measured training time
        for c in d.get("claims", []):
            if c.get("id") == "Q6" and isinstance(c.get("headline"), dict):
                c["headline"].pop("value", None); c["headline"].pop("per_seed", None); c["headline"].pop("spread", None)
                c.get("numbers", {}).pop("over_authors", None)  # our training time over the authors' (a timing)
    walk(da, db, fa.parent.name, out, pairs)
    largest, other = summary(pairs)
    extra = len(out) - len(pairs)  # a key or a list entry on one side only
    print(f"{fa.parent.name}: {len(out)} differences" + (f" (numbers: largest relative {largest:.1e}; "
                                                          f"not numbers: {other + extra})" if out else ""))
    for line in out[:show]:
        print("   ", line)
    bad += bool(out)
for fb in sorted(rb.glob("*/results.json")):
    if not (ra / fb.parent.name / "results.json").exists():
        print(f"{fb.parent.name}: missing in A"); bad += 1
sys.exit(1 if bad else 0)
