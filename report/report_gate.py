"""The report's performance gate (report/make_report.py; docs/bench-format.md,
"Performance gate"): NEW beside BASE per point, decided on the repetitions with a one-sided
Mann-Whitney U test and a time-ratio interval; its section, summary lines and CSV."""

import collections
import functools
import io
import json
import math
import os
import statistics

from report_common import csv_writer, fail, load_mark, load_warning, np, num, printable


GATE_MIN_REPS = 5
LEVEL_RANGE = (1e-6, 0.25)  # --level, as `octocd report --level` takes it (1e-6: 12 repetitions a side)
EXACT_COST = 1 << 18  # min(m, n) * m * n at most: U's exact null distribution (0.03 s of Python at 64 a side, cached)
SMALL_PAIRS = 4096  # m * n at most: U and the pairwise ratios in plain Python (cheaper than numpy per call)
DIRECT_PAIRS = 1 << 22  # m * n at most: the pairwise log ratios held at once (32 MiB); beyond, found by bisection


def median(v):
    """The median of a list of numbers as numpy's (the mean of the two middle values when
    even), without numpy's overhead on a few values."""
    s = sorted(v)
    k = len(s) // 2
    return float(s[k]) if len(s) % 2 else (s[k - 1] + s[k]) / 2.0


def exact_is_cheap(m, n):
    """Whether U's exact null distribution is used for samples of m and n (its cost grows as
    min(m, n) * m * n; scipy's exact method asked for 12 GiB at 200 a side)."""
    return min(m, n) * m * n <= EXACT_COST


def u_null_sf_counts(m, n):
    """Counts of U = 0 .. m*n under H0 for samples of m and n (no ties): the coefficients of
    the Gaussian binomial [m+n choose m]_q = prod_{i=1..m} (1 - q^(n+i)) / (1 - q^i)."""
    c = [1] + [0] * (m * n)
    for i in range(1, m + 1):
        for k in range(m * n, n + i - 1, -1):  # times (1 - q^(n+i))
            c[k] -= c[k - n - i]
        for k in range(i, m * n + 1):  # divided by (1 - q^i)
            c[k] += c[k - i]
    return c


@functools.lru_cache(maxsize=64)
def u_null_sf(m, n):
    """P(U >= k) for k = 0 .. m*n + 1 under H0 (no ties), exact (integer counts, each
    probability correctly rounded); U's distribution for (m, n) is that for (n, m)."""
    m, n = min(m, n), max(m, n)
    counts = u_null_sf_counts(m, n)
    total, tail = sum(counts), 0
    sf = [0.0] * (m * n + 2)
    for k in range(m * n, -1, -1):
        tail += counts[k]
        sf[k] = tail / total
    return tuple(sf)


def u_statistic(x, y):
    """(U, tie term) of sample x against y: U = pairs x_i > y_j, ties counted a half (the
    rank-sum U of scipy.stats.mannwhitneyu); the tie term sum(t^3 - t) over the groups of
    equal values of x and y together (the normal approximation's tie correction)."""
    m, n = len(x), len(y)
    if m * n <= SMALL_PAIRS:
        u = 0.0
        for a in x:
            for b in y:
                u += 1.0 if a > b else 0.5 if a == b else 0.0
        counts = collections.Counter(x)
        counts.update(y)
        return u, float(sum(t ** 3 - t for t in counts.values() if t > 1))
    from scipy.stats import rankdata
    z = np.concatenate([np.asarray(x, dtype=float), np.asarray(y, dtype=float)])
    u = float(rankdata(z)[:m].sum()) - m * (m + 1) / 2.0
    t = np.unique(z, return_counts=True)[1].astype(float)
    return u, float((t ** 3 - t).sum())


def u_sf(u, m, n, tie=0.0):
    """P(U >= u) under H0 ("no difference"), the one-sided p of U = u: exact where cheap
    (exact_is_cheap; as scipy's method "exact", U rounded down and ties not corrected), else
    the normal approximation with continuity and tie correction (scipy's "asymptotic")."""
    if exact_is_cheap(m, n):
        return u_null_sf(m, n)[max(0, min(int(u), m * n + 1))]
    return u_sf_normal(u, m, n, tie)


def u_sf_normal(u, m, n, tie=0.0):
    """u_sf's normal approximation (any m, n): z = (U - mn/2 - 1/2) / sigma, sigma^2 =
    mn/12 ((N + 1) - tie / (N (N - 1))), N = m + n; p = P(Z >= z)."""
    big_n = m + n
    s = math.sqrt(m * n / 12.0 * ((big_n + 1) - tie / (big_n * (big_n - 1))))
    num = u - m * n / 2.0 - 0.5
    if not s > 0:  # every value equal: U = mn/2
        return 1.0 if num <= 0 else 0.0
    return 0.5 * math.erfc(num / s / math.sqrt(2.0))


def min_p(m, n):
    """The smallest p the one-sided test can give samples of m and n (every new time above
    every baseline time): 1 / C(m+n, m) exactly, or its normal approximation."""
    if exact_is_cheap(m, n):
        return 1 / math.comb(m + n, m)
    return u_sf_normal(m * n, m, n)


def reps_needed(alpha):
    """The repetitions a side (>= GATE_MIN_REPS) whose smallest p is below alpha (monotone in
    the count for levels in LEVEL_RANGE)."""
    k = GATE_MIN_REPS
    while k < 100000 and not min_p(k, k) < alpha:
        k += 1
    return k


def u_critical(m, n, alpha):
    """The smallest c with P(U >= c) <= alpha under H0 (no ties), or None when no c is (too
    few repetitions): exact where cheap, else from the normal approximation."""
    if exact_is_cheap(m, n):
        sf = u_null_sf(m, n)
        if sf[m * n] > alpha:
            return None
        lo, hi = 0, m * n  # sf decreases: the first c with sf[c] <= alpha
        while lo < hi:
            mid = (lo + hi) // 2
            if sf[mid] <= alpha:
                hi = mid
            else:
                lo = mid + 1
        return lo
    z = -statistics.NormalDist().inv_cdf(alpha)
    c = math.ceil(m * n / 2.0 + 0.5 + z * math.sqrt(m * n * (m + n + 1) / 12.0))
    return c if c <= m * n else None


def pairwise_order_stats(a, b, ks):
    """The k-th smallest (1-based) of the m*n differences a_i - b_j for each k of ks: all of
    them sorted or partitioned while m*n <= DIRECT_PAIRS, else by bisection on the value with
    pair counts from the sorted samples (to 1e-13 absolute: ratios to 1e-13 relative)."""
    m, n = len(a), len(b)
    if m * n <= SMALL_PAIRS:
        d = sorted(x - y for x in a for y in b)
        return [d[k - 1] for k in ks]
    if m * n <= DIRECT_PAIRS:
        d = np.subtract.outer(np.asarray(a, dtype=float), np.asarray(b, dtype=float)).ravel()
        part = np.partition(d, sorted({k - 1 for k in ks}))
        return [float(part[k - 1]) for k in ks]
    sa, sb = np.sort(np.asarray(a, dtype=float)), np.sort(np.asarray(b, dtype=float))
    out = []
    for k in ks:
        lo, hi = float(sa[0] - sb[-1]) - 1.0, float(sa[-1] - sb[0])  # count(lo) < k <= count(hi)
        while hi - lo > 1e-13:
            mid = 0.5 * (lo + hi)
            if mid <= lo or mid >= hi:
                break
            below = int(n * m - np.searchsorted(sb, sa - mid, side="left").sum())  # pairs with a_i - b_j <= mid
            if below >= k:
                hi = mid
            else:
                lo = mid
        out.append(hi)
    return out


def ratio_interval(new_t, base_t, alpha):
    """Hodges-Lehmann ratio new/base with its 1 - 2 alpha interval (from U's critical value)."""
    ln = [math.log(x) for x in new_t]
    lb = [math.log(y) for y in base_t]
    mn = len(ln) * len(lb)
    c = u_critical(len(new_t), len(base_t), alpha)
    mid = [(mn + 1) // 2] if mn % 2 else [mn // 2, mn // 2 + 1]
    ks = mid + ([mn - c + 1, c] if c is not None else [])
    q = pairwise_order_stats(ln, lb, ks)
    est = math.exp(sum(q[:len(mid)]) / len(mid))
    if c is None:
        return est, 0.0, math.inf
    return est, math.exp(q[len(mid)]), math.exp(q[len(mid) + 1])


def gate_test(new_t, base_t, threshold, alpha):
    """One figure: (verdict, p_slower, ratio, lo, hi). p_slower: one-sided Mann-Whitney U of
    new times against baseline times x (1 + threshold/100) (u_sf: exact where cheap, the
    normal approximation with tie correction beyond)."""
    f = 1.0 + threshold / 100.0
    m, n = len(new_t), len(base_t)
    u, tie = u_statistic(new_t, [y * f for y in base_t])
    p_slow = u_sf(u, m, n, tie)
    u, tie = u_statistic([x * f for x in new_t], base_t)
    p_fast = u_sf(m * n - u, m, n, tie)  # the mirrored test: U of the baseline's side
    ratio, lo, hi = ratio_interval(new_t, base_t, alpha)
    if p_slow < alpha:
        verdict = "SLOWER"
    elif p_fast < alpha:
        verdict = "faster"
    elif lo >= 1.0 / f and hi <= f:
        verdict = "same"
    else:
        verdict = "not shown slower"
    return verdict, p_slow, ratio, lo, hi


def timing_of(p, cpu=False):
    """[(label, spread, higher_is_better)] of a point: steps/s per window (with cpu: steps per
    process CPU second, where the point has them), or replay ms/frame."""
    out = []
    if isinstance(p.get("windows"), dict):
        for wn, w in p["windows"].items():
            if cpu and isinstance(w, dict) and "cpu_steps_per_s" in w:
                out.append((f"CPU steps/s ({wn})", w["cpu_steps_per_s"], True))
            else:
                out.append((f"steps/s ({wn})", w.get("steps_per_s") if isinstance(w, dict) else None, True))
    elif "ms_per_frame" in p:
        out.append(("broadphase ms/frame", p["ms_per_frame"], False))
    return out


def has_cpu_timing(p):
    w = p.get("windows")
    return isinstance(w, dict) and bool(w) and all(isinstance(x, dict) and "cpu_steps_per_s" in x for x in w.values())


def machine_text(j):
    m, b = j["machine"], j["build"]
    return f"{m.get('hostname')} ({m.get('cpu')}), build {b.get('build_id')}"


def finite_positive(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0


def repetitions(spread, where, side_file):
    """The raw repetitions of a spread, checked against its stored summary (median, min, max,
    n): a summary that does not match its repetitions (an edited or forged file) is bad input.
    Values may be non-finite or <= 0 (the caller judges them)."""
    if not isinstance(spread, dict) or not isinstance(spread.get("values"), list):
        fail(f"{side_file}: {where}.values: missing; allowed: a spread with its repetitions (octocd bench writes "
             "them; the gate decides on the repetitions, never on stored ranges)")
    vals = spread["values"]
    nums = [v for v in vals if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)]
    if len(nums) == len(vals) and vals:
        expect = {"n": len(vals), "median": median(vals), "min": min(vals), "max": max(vals)}
        for k, e in expect.items():
            got = spread.get(k)
            if not isinstance(got, (int, float)) or isinstance(got, bool) or \
                    not math.isclose(got, e, rel_tol=1e-9, abs_tol=1e-300):
                fail(f"{side_file}: {where}.{k}: {got!r}, but its {len(vals)} repetitions give {e!r}; allowed: a "
                     "summary that matches its values (an edited or forged result is refused)")
    elif spread.get("n") != len(vals):
        fail(f"{side_file}: {where}.n: {spread.get('n')!r}, but it holds {len(vals)} values; allowed: n = the "
             "number of values")
    return vals


def check_same_sweep(base, new, across):
    bj, nj = base["first"], new["first"]
    for key, what in (("name", "sweep.name"), ("definition", "sweep.definition")):
        if bj["sweep"].get(key) != nj["sweep"].get(key):
            fail(f"{base['files'][0]}: {what}: baseline of another sweep ({bj['sweep'].get('name')!r} vs "
                 f"{nj['sweep'].get('name')!r} in {new['files'][0]}); allowed: a baseline of the same sweep definition")
    bm, nm = bj["machine"], nj["machine"]
    if (bm.get("hostname"), bm.get("cpu")) != (nm.get("hostname"), nm.get("cpu")) and not across:
        fail(f"{new['files'][0]}: machine: {nm.get('hostname')!r} ({nm.get('cpu')}), but the baseline "
             f"{base['files'][0]} ran on {bm.get('hostname')!r} ({bm.get('cpu')}); allowed: runs of one machine, or "
             "--across-machines (a ratio then mixes the machines' speed with the builds')")
    return (bm.get("hostname"), bm.get("cpu")) != (nm.get("hostname"), nm.get("cpu"))


def stopped_text(g):
    """Why a side's result is not a finished run ('' when it is)."""
    why = []
    for path in g["files"]:
        j = g["json"][path]
        if j.get("stopped"):
            why.append(f"{path}: stopped by {j['stopped']}")
        elif j.get("complete") is not True:
            why.append(f"{path}: complete: {json.dumps(j.get('complete'))} (an interrupted or unfinished run)")
    return "; ".join(why)


def gate_decide(base, new, threshold, alpha, across=False, timing="auto"):
    """NEW beside BASE per point and timing figure. Returns a dict: rows (one per point and
    figure, numbers), broken (points of the baseline the new run lacks, failed, skipped or
    measured as non-finite or <= 0: exit 4), few (figures with < 5 repetitions a side: exit 2),
    frames (points whose runs timed other frames, the time budget's cuts: exit 2),
    slower (rows SLOWER: exit 4), across, notes. Bad input (another sweep, another machine
    without `across`, a forged summary, a broken baseline) exits 2 here."""
    across = check_same_sweep(base, new, across)
    bwhy = stopped_text(base)
    if bwhy:
        fail(f"--baseline: {bwhy}; allowed: a finished run of `octocd bench` as the baseline")
    out = {"rows": [], "broken": [], "few": [], "frames": [], "slower": [], "across": across, "notes": []}
    nwhy = stopped_text(new)
    if nwhy:
        out["broken"].append(("the new run", f"not a finished run: {nwhy}"))
    newp = new["points"]
    def runs_of(g, pid):
        """[(file, point)] of a point: one per run of the side (several runs pooled)."""
        return g["pooled"].get(pid) or [(g["origin"][pid], g["points"][pid])]

    for q in base["points_list"]:
        st = {x.get("status") for _, x in runs_of(base, q["id"])}
        if "ok" in st and len(st) > 1:
            fail(f"--baseline: '{q['id']}': ok in some runs, {', '.join(sorted(st - {'ok'}))} in others "
                 f"({', '.join(f for f, _ in runs_of(base, q['id']))}); allowed: a baseline whose runs measured it")
    base_ok = [p for p in base["points_list"] if p.get("status") == "ok"]
    if not base_ok:
        fail(f"--baseline {base['files'][0]}: no measured point (every point failed or skipped); allowed: a baseline "
             "with measured points")
    index_of = {x["id"]: k for k, x in enumerate(base["points_list"])}
    for q in base_ok:
        pid = q["id"]
        bfile = base["origin"][pid]
        p = newp.get(pid)
        if p is None:
            out["broken"].append((pid, "missing in the new run"))
            continue
        nfile = new["origin"][pid]
        bad = [(f, x) for f, x in runs_of(new, pid) if x.get("status") != "ok"]
        if bad:
            f, x = bad[0]
            out["broken"].append((pid, f"{x.get('status')} in the new run ({f}): {x.get('reason', 'no reason')}"))
            continue
        # Steps per process CPU second where both runs have them (host engines: the load of
        # other processes on a shared machine hardly moves them), else wall-clock steps/s.
        cpu = timing == "cpu" or (timing == "auto" and has_cpu_timing(q) and has_cpu_timing(p))
        if timing == "cpu" and not (has_cpu_timing(q) and has_cpu_timing(p)):
            fail(f"--timing cpu: '{pid}' has no cpu_steps_per_s in "
                 + (base["origin"][pid] if not has_cpu_timing(q) else new["origin"][pid])
                 + "; allowed: results of a bench that records them (host engines), or --timing auto|wall")
        bt, nt = timing_of(q, cpu), timing_of(p, cpu)
        if [x[0] for x in bt] != [x[0] for x in nt]:
            out["broken"].append((pid, f"the new run ({nfile}) has figures {[x[0] for x in nt]}, the baseline "
                                       f"{[x[0] for x in bt]}"))
            continue
        # Steps/s over other frames (the time budget cut the runs' windows differently) are
        # not like with like: no verdict (docs/bench-format.md "Time budget").
        spans = {}
        for side in (base, new):
            for f, x in runs_of(side, pid):
                w = x.get("windows")
                if isinstance(w, dict):
                    spans.setdefault(tuple((wn, v.get("first"), v.get("last")) if isinstance(v, dict) else (wn,)
                                           for wn, v in w.items()), f)
        if len(spans) > 1:
            out["frames"].append((pid, "; ".join(f"{f}: " + ", ".join(
                f"{s[0]} frames {s[1]}-{s[2]}" if len(s) == 3 else str(s[0]) for s in span)
                for span, f in spans.items())))
            continue
        i = index_of[pid]
        for k, ((label, bs, hib), (_, ns, _)) in enumerate(zip(bt, nt)):
            key = ("cpu_steps_per_s" if label.startswith("CPU") else "steps_per_s") if hib else "ms_per_frame"
            # Every run of a side: its repetitions pooled (each run's summary checked).
            bv, nv = [], []
            for side, vals in ((base, bv), (new, nv)):
                for f, x in runs_of(side, pid):
                    tx = timing_of(x, cpu)
                    if k >= len(tx) or tx[k][0] != label:
                        out["broken"].append((pid, f"{f} has figures {[t[0] for t in tx]}, expected {label}"))
                        continue
                    vals += repetitions(tx[k][1], f"point '{pid}' {label}", f)
            bad_b = [v for v in bv if not finite_positive(v)]
            if bad_b:
                fail(f"{bfile}: points[{i}] '{pid}' {label}: repetition(s) {bad_b[:3]}; allowed: finite figures > 0 "
                     "in the baseline")
            bad_n = [v for v in nv if not finite_positive(v)]
            if bad_n or not nv:
                out["broken"].append((pid, f"{label} in the new run ({nfile}): "
                                           + (f"repetition(s) {', '.join(str(v) for v in bad_n[:3])}: not finite "
                                              "and > 0" if bad_n else "no repetitions")))
                continue
            if min(len(bv), len(nv)) < GATE_MIN_REPS:
                out["few"].append((pid, label, len(bv), len(nv), None))
                continue
            if not min_p(len(nv), len(bv)) < alpha:  # no slowdown could be shown at this level
                out["few"].append((pid, label, len(bv), len(nv), min_p(len(nv), len(bv))))
                continue
            bt_s = [1.0 / v for v in bv] if hib else list(bv)
            nt_s = [1.0 / v for v in nv] if hib else list(nv)
            verdict, pval, ratio, lo, hi = gate_test(nt_s, bt_s, threshold, alpha)
            row = {"point": pid, "figure": label, "key": key, "base": bv, "new": nv, "base_median": median(bv),
                   "new_median": median(nv), "ratio": ratio, "lo": lo, "hi": hi, "p": pval,
                   "verdict": verdict}
            out["rows"].append(row)
            if verdict == "SLOWER":
                out["slower"].append(row)
    base_ids = {p["id"] for p in base_ok}
    extra = [p["id"] for p in new["points_list"] if p["id"] not in base_ids and p.get("status") == "ok"]
    if extra:
        out["notes"].append(f"{len(extra)} point(s) of the new run not measured in the baseline (not gated): "
                            + ", ".join(extra))
    return out


def section_gate(doc, base, new, threshold, alpha, across, timing="auto"):
    """The gate's section of the report; returns gate_decide's result."""
    res = gate_decide(base, new, threshold, alpha, across, timing)
    bj, nj = base["first"], new["first"]
    doc.section = "gate"
    doc.h(2, f"Performance gate: {nj['sweep']['name']}", "gate")
    conf = 100.0 * (1.0 - 2.0 * alpha)
    doc.p(f"Baseline: {machine_text(bj)}, {', '.join(os.path.basename(f) for f in base['files'])}. "
          f"New: {machine_text(nj)}, {', '.join(os.path.basename(f) for f in new['files'])}. "
          + (f"Across machines (--across-machines): {bj['machine'].get('hostname')} vs "
             f"{nj['machine'].get('hostname')}: a ratio mixes the machines' speed with the builds'. "
             if res["across"] else "Same machine. ")
          + f"Ratio = new time / baseline time (> 1 slower): the median of the pairwise ratios of the repetitions "
          f"(Hodges-Lehmann) with its {conf:g} % interval. A figure is SLOWER (exit 4) when the one-sided "
          f"Mann-Whitney U test of the new times against the baseline times x {1 + threshold / 100:g} rejects at level "
          f"{alpha:g} (p < {alpha:g}): slower by more than {threshold:g} % with confidence; 'same' when the interval "
          f"lies within {threshold:g} % either way; 'not shown slower' otherwise (passes). At least "
          f"{GATE_MIN_REPS} repetitions a side; a baseline point the new run lacks, failed, skipped or measured as "
          "non-finite or <= 0 fails the gate (exit 4).")
    warn = [f"{side}: {w}" for side, w in (("baseline", load_warning(bj["machine"])),
                                            ("new", load_warning(nj["machine"]))) if w]
    rows = [[r["point"], r["figure"], f"{num(r['base_median'])} (n={len(r['base'])})",
             f"{num(r['new_median'])} (n={len(r['new'])})", f"{r['ratio']:.3f}", f"{r['lo']:.3f}–{r['hi']:.3f}",
             f"{r['p']:.3g}", (load_mark(bj["machine"], base["points"].get(r["point"]))
                               or load_mark(nj["machine"], new["points"].get(r["point"]))
                               if r["verdict"] != "same" else "") + r["verdict"]] for r in res["rows"]]
    rows += [[pid, "", "", "", "", "", "", "FAILED: " + why] for pid, why in res["broken"]]
    doc.table(["point", "figure", "baseline median", "new median", "ratio (time)", f"{conf:g} % interval",
               "p (slower)", "verdict"], rows,
              ("Measured under load: " + "; ".join(warn) + ". " if warn else "") + " ".join(res["notes"]),
              name="gate")
    counts = {}
    for r in res["rows"]:
        counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
    doc.p("Verdicts: " + ", ".join(f"{v} {c}" for v, c in sorted(counts.items()))
          + (f", FAILED {len(res['broken'])}" if res["broken"] else "") + "." if counts or res["broken"]
          else "No point measured in both runs.")
    if doc.csv_dir:
        gate_csv(doc, os.path.join(doc.csv_dir, "gate.csv"), res)
        doc.ncsv += 1
    return res


# ---- CSV: the data, numbers only ---------------------------------------------------------------


def gate_summary(res, threshold, alpha):
    """The gate's verdict on stdout: every failed and every slower point named."""
    conf = 100.0 * (1.0 - 2.0 * alpha)
    for pid, why in res["broken"]:
        print(printable(f"octocd report: gate: FAILED: {pid}: {why}"))
    for r in res["slower"]:
        print(f"octocd report: gate: SLOWER: {printable(r['point'])}: {r['figure']}: time ratio {r['ratio']:.3f} "
              f"({conf:g} % interval {r['lo']:.3f}-{r['hi']:.3f}; Mann-Whitney U p = {r['p']:.3g} against "
              f"{1 + threshold / 100:g}x)")
    n = len(res["rows"])
    if res["broken"]:
        print(f"octocd report: gate: FAILED: {len(res['broken'])} point(s) of the baseline missing, failed, skipped "
              f"or not measured in the new run" + (f"; {len(res['slower'])} of {n} figure(s) SLOWER" if res["slower"]
                                                  else ""))
    elif res["slower"]:
        print(f"octocd report: gate: FAILED: {len(res['slower'])} of {n} figure(s) SLOWER by more than "
              f"{threshold:g} % (one-sided Mann-Whitney U, level {alpha:g})")
    else:
        print(f"octocd report: gate: passed: {n} figure(s), none shown slower by more than {threshold:g} % "
              f"(one-sided Mann-Whitney U, level {alpha:g})")


def gate_csv(doc, path, res):
    """The gate as data: per point and figure one row per side and repetition (kind rep) and
    one summary row (kind summary: both medians, ratio, interval, p, slower 0/1)."""
    f = io.StringIO(newline="")
    if True:
        w = csv_writer(f)
        w.writerow(["point", "figure", "kind", "side", "repetition", "value", "unit", "base_median", "new_median",
                    "ratio_time", "ratio_lo", "ratio_hi", "p_slower", "slower"])
        for r in res["rows"]:
            unit = "ms" if r["key"] == "ms_per_frame" else "1/s"
            for side in ("base", "new"):
                for k, v in enumerate(r[side]):
                    w.writerow([r["point"], r["figure"], "rep", side, k, repr(float(v)), unit] + [""] * 7)
            w.writerow([r["point"], r["figure"], "summary", "", "", "", unit, repr(r["base_median"]),
                        repr(r["new_median"]), repr(r["ratio"]), repr(r["lo"]), repr(r["hi"]), repr(r["p"]),
                        int(r["verdict"] == "SLOWER")])
    doc.files.put(path, f.getvalue())
