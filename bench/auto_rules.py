#!/usr/bin/env python3
"""Decision rules for `method = "auto"` tried on the evidence the auto grid records.

`EVIDENCE=ev.jsonl SEEDS=1,2,3 cargo bench --bench auto_grid` appends, per case,
every candidate's held-out record, noise, uncertainty and the mapping error
between every two candidates' lenses, with each candidate's mapping error to the
true lens. This script replays rules on those records, so that a threshold can
be fitted on some seeds and judged on others without solving again:

    python3 bench/auto_rules.py ev.jsonl --fit 1,2,3 --eval 100,200

It prints, per rule and seed set, the regret (chosen candidate's error over the
best candidate's), the confusion matrix and the cases that miss a target.
"""
import argparse
import json
import math
import statistics

NAMES = ["standard", "dynamic", "full"]


def load(path):
    cases = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line:
                case = json.loads(line)
                # A failed candidate's error is written as null (infinite).
                case["errors"] = [math.inf if e is None else e for e in case["errors"]]
                cases.append(case)
    return cases


def mse(c):
    n = sum(c["cv_n"])
    return sum(c["cv_sq"]) / max(n, 1)


def paired_noise(a, b):
    """Standard error of mse(a) - mse(b), px^2, paired over frames (as the Rust rule)."""
    total = sum(a["cv_n"])
    d = [x - y for x, y, n in zip(a["cv_sq"], b["cv_sq"], a["cv_n"]) if n > 0]
    if len(d) < 2 or total == 0:
        return math.inf
    m = sum(d) / len(d)
    var = sum((x - m) ** 2 for x in d) / (len(d) - 1)
    return math.sqrt(len(d) * var) / total


def cv_rule(case, k=1.0):
    """Lowest held-out error unless a simpler candidate is within k paired SE."""
    cs = case["candidates"]
    ok = [i for i, c in enumerate(cs) if c["cv_sq"] is not None]
    best = min(ok, key=lambda i: mse(cs[i]))
    for i in ok:
        if i < best and mse(cs[i]) - mse(cs[best]) <= k * paired_noise(cs[i], cs[best]):
            return i
    return best


def cv2_rule(case, k_std, k_bend):
    """As cv_rule, with k_std standard errors for keeping `standard` and k_bend for
    keeping a simpler bending candidate (dynamic against full)."""
    cs = case["candidates"]
    ok = [i for i, c in enumerate(cs) if c["cv_sq"] is not None]
    best = min(ok, key=lambda i: mse(cs[i]))
    for i in ok:
        k = k_std if i == 0 else k_bend
        if i < best and mse(cs[i]) - mse(cs[best]) <= k * paired_noise(cs[i], cs[best]):
            return i
    return best


def risk(case, ref, i, var_key="e2"):
    """Estimated squared mapping error to the truth of candidate i, with `ref` taken
    as unbiased: its variance, and for i the shift to ref beyond what the extra
    variance of ref explains (Hausman / focused information criterion)."""
    cs = case["candidates"]
    vr, vi = cs[ref][var_key], cs[i][var_key]
    if vr is None or vi is None or case["shift"][i][ref] is None:
        return None
    if i == ref:
        return vr
    s2 = case["shift"][i][ref] ** 2
    return max(0.0, s2 - max(vr - vi, 0.0)) + vi


def fic_rule(case, ref_kind="cv", k=1.0, c=1.0, var_key="e2"):
    """Reference = the CV rule's choice (or the most complex); a simpler candidate
    replaces it where its estimated risk is below c times the reference's."""
    cs = case["candidates"]
    if ref_kind == "cv":
        ref = cv_rule(case, k)
    elif ref_kind == "cvbest":
        ref = cv_rule(case, 0.0)
    else:
        ref = len(cs) - 1
    rr = risk(case, ref, ref, var_key)
    if rr is None:
        return ref
    best, best_risk = ref, c * rr
    for i in range(ref):
        r = risk(case, ref, i, var_key)
        if r is not None and r < best_risk:
            best, best_risk = i, r
    return best


def targets(case, chosen):
    e = case["errors"]
    best = min(e)
    miss = []
    regret = e[chosen] / best
    if regret > 1.3:
        miss.append("regret %.2f" % regret)
    if case["board"] == "rigid" and case["print_mm"] == 0.0 and e[chosen] > 1.1 * e[0]:
        miss.append("rigid, %.0f%% worse than standard" % (100 * (e[chosen] / e[0] - 1)))
    if chosen == 0 and e[0] > 2 * best:
        miss.append("standard 2x worse than best")
    return regret, miss


def judge(cases, rule, show=False):
    regrets, misses = [], 0
    confusion = [[0] * 3 for _ in range(3)]
    lines = []
    for case in cases:
        chosen = rule(case)
        r, m = targets(case, chosen)
        regrets.append(r)
        b = min(range(3), key=lambda i: case["errors"][i])
        confusion[b][chosen] += 1
        if m:
            misses += 1
            lines.append("  %s %s %d fr %.1f px %s seed %d: chose %s (%s) errors %s; %s" % (
                case["board"], case["print_mm"], case["frames"], case["noise_px"],
                case["model"], case["seed"], NAMES[chosen], case["chosen"],
                " ".join("%.3f" % x for x in case["errors"]), "; ".join(m)))
    regrets.sort()
    n = len(regrets)
    out = "median %.3f, p90 %.3f, worst %.3f, %d/%d cases miss" % (
        statistics.median(regrets), regrets[min(n - 1, n * 9 // 10)], regrets[-1], misses, n)
    if show:
        out += "\n  best\\chosen " + " ".join("%8s" % x for x in NAMES)
        for b in range(3):
            out += "\n  %-11s " % NAMES[b] + " ".join("%8d" % x for x in confusion[b])
        out += "\n" + "\n".join(lines)
    return out, misses, regrets[-1]


def hausman_rule(case, k=1.0, z=1.0, key="shift_rot", var="e2_rot"):
    """Reference = the CV rule's choice; a simpler candidate whose lens differs from
    the reference's by less than z times their combined sigma replaces it."""
    cs = case["candidates"]
    ref = cv_rule(case, k)
    for i in range(ref):
        vi, vr = cs[i][var], cs[ref][var]
        if vi is None or vr is None:
            continue
        if case[key][i][ref] is not None and case[key][i][ref] < z * math.sqrt(vi + vr):
            return i
    return ref


RULES = {
    "as recorded": None,
}
for i, n in enumerate(NAMES):
    RULES["always " + n] = lambda c, i=i: i
for k in [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0]:
    RULES["cv k=%.1f" % k] = lambda c, k=k: cv_rule(c, k)
for k0 in [0.5, 1.0, 2.0, 3.0]:
    for k1 in [1.0, 2.0, 3.0, 4.0, 6.0]:
        RULES["cv2 k0=%.1f k1=%.1f" % (k0, k1)] = lambda c, k0=k0, k1=k1: cv2_rule(c, k0, k1)
for k in [1.0, 2.0]:
    for z in [0.5]:
        RULES["hausman rot k=%.0f z=%.1f" % (k, z)] = (
            lambda c, k=k, z=z: hausman_rule(c, k, z))
        RULES["hausman plain k=%.0f z=%.1f" % (k, z)] = (
            lambda c, k=k, z=z: hausman_rule(c, k, z, "shift", "e2"))
for cc in [1.0]:
    RULES["fic ref=cv c=%.2f" % cc] = lambda c, cc=cc: fic_rule(c, "cv", 1.0, cc)


def per_board(cases, rule):
    """Geometric means of every candidate's and the rule's error, per board."""
    out = []
    boards = []
    for c in cases:
        if c["board"] not in boards:
            boards.append(c["board"])
    for b in boards:
        sub = [c for c in cases if c["board"] == b]
        gm = lambda f: math.exp(sum(math.log(f(c)) for c in sub) / len(sub))
        regrets = sorted(c["errors"][rule(c)] / min(c["errors"]) for c in sub)
        chose = [sum(1 for c in sub if rule(c) == i) for i in range(3)]
        out.append("| %s | %s | %.3f | %.3f / %.3f | %d / %d / %d |" % (
            b, " | ".join("%.3f" % gm(lambda c, i=i: c["errors"][i]) for i in range(3)),
            gm(lambda c: c["errors"][rule(c)]), statistics.median(regrets), regrets[-1],
            *chose))
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("evidence", nargs="+")
    ap.add_argument("--fit", default="1,2,3")
    ap.add_argument("--eval", default="100,200")
    ap.add_argument("--show", default="")
    a = ap.parse_args()
    cases = [c for p in a.evidence for c in load(p)]
    fit = {int(s) for s in a.fit.split(",")}
    ev = {int(s) for s in a.eval.split(",")}
    RULES["as recorded"] = lambda c: NAMES.index(c["chosen"])
    # What no rule can beat: knowing the kind of board (shape, size, print error,
    # lens, noise; not the seed), the candidate of lowest geometric-mean error.
    def kind(c):
        return (c["board"], c["print_mm"], c["frames"], c["noise_px"], c["model"])
    groups = {}
    for c in cases:
        groups.setdefault(kind(c), []).append(c)
    oracle = {
        k: min(range(3), key=lambda i: sum(math.log(c["errors"][i]) for c in g))
        for k, g in groups.items()
    }
    RULES["oracle of the kind"] = lambda c: oracle[kind(c)]
    for label, seeds in [("fit", fit), ("eval", ev)]:
        sub = [c for c in cases if c["seed"] in seeds]
        if not sub:
            continue
        print("== %s seeds %s: %d cases" % (label, sorted(seeds), len(sub)))
        for name, rule in RULES.items():
            print("%-24s %s" % (name, judge(sub, rule, name == a.show)[0]))
        if a.show:
            print(per_board(sub, RULES[a.show]))


if __name__ == "__main__":
    main()
