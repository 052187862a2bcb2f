#!/usr/bin/env python3
"""Margins of the shipped models on the validation and test sets (docs/protocol.md), from the
records of `scripts/results.sh holdout`: per light field and as each set's worst case, in the
terms the targets are stated in. Usage: scripts/holdout-margins.py [RECORDS.jsonl]
(default results/holdout/records.jsonl). Grey networks other than the shipped ones (added by
`scripts/results.sh holdout-add`) get a row of their margin over pinv each."""
import json
import sys
from collections import defaultdict

LEARNED = ("lfnet-learned-mask-n2-full-l3", "lfnet-learned-asp-n2-full")
SELF_ENSEMBLE = "self-ensemble, lfnet-asp-n2-auto"
COLOUR = "Bayer RGGB, hard-dark-blend"  # the zoo's colour default


def load(path):
    psnr = defaultdict(dict)  # light field -> key -> PSNR
    role = {}
    for line in open(path):
        if not line.strip():
            continue
        r = json.loads(line)
        lf = r["light_field"]
        role[lf] = r.get("set", {}).get("role", "")
        noise = r.get("noise_sigma", 0) or 0
        key = (r["method"], r.get("variant", ""), round(noise, 4))
        psnr[lf][key] = r["psnr_db"]
    return psnr, role


def rows_of(psnr):
    """(label, function of one light field's PSNRs -> margin or None)."""
    def get(p, method, variant="", noise=0.0):
        return p.get((method, variant, noise))

    def diff(a, b):
        return None if a is None or b is None else a - b

    def best_colour_pinv(p):
        return max(filter(None, [get(p, "pinv", "Bayer RGGB"),
                                 get(p, "pinv", "Bayer RGGB, malvar")]), default=None)

    rows = [
        ("lfnet-asp-n2 - pinv",
         lambda p: diff(get(p, "net", "lfnet-asp-n2"), get(p, "pinv"))),
        ("colour default, one pass - (pinv + better demosaic)",
         lambda p: diff(get(p, "net", COLOUR), best_colour_pinv(p))),
        ("colour default, four-pass self-ensemble - (pinv + better demosaic)",
         lambda p: diff(get(p, "net", COLOUR + ", self-ensemble"), best_colour_pinv(p))),
        ("learned mask - lfnet-asp-n2",
         lambda p: diff(get(p, "net", LEARNED[0]), get(p, "net", "lfnet-asp-n2"))),
        ("learned ASP - lfnet-asp-n2",
         lambda p: diff(get(p, "net", LEARNED[1]), get(p, "net", "lfnet-asp-n2"))),
        ("noise-aware lfnet-asp-n2-noise - pinv",
         lambda p: diff(get(p, "net", "lfnet-asp-n2-noise"), get(p, "pinv"))),
        ("grey default lfnet-asp-n2-auto (noise switch) blind, noiseless sensor - pinv",
         lambda p: diff(get(p, "net", "lfnet-asp-n2-auto, estimated"), get(p, "pinv"))),
        ("grey default, four-pass self-ensemble (--self-ensemble) - pinv",
         lambda p: diff(get(p, "net", SELF_ENSEMBLE), get(p, "pinv"))),
        ("noise switch blind - pinv-nlm told, sigma 0.05",
         lambda p: diff(get(p, "net", "lfnet-asp-n2-auto, estimated", 0.05),
                        get(p, "pinv-nlm", "", 0.05))),
        ("noise switch blind - told, sigma 0.05",
         lambda p: diff(get(p, "net", "lfnet-asp-n2-auto, estimated", 0.05),
                        get(p, "net", "lfnet-asp-n2-auto, told", 0.05))),
        ("no-parallax - pinv", lambda p: diff(get(p, "no-parallax"), get(p, "pinv"))),
    ]
    extra = sorted({k[1] for p in psnr.values() for k in p
                    if k[0] == "net" and k[2] == 0 and k[1] not in ("lfnet-asp-n2", "lfnet-asp-n2-noise",
                                                    "lfnet-asp-n2-auto, estimated",
                                                    "lfnet-asp-n2-auto, told", SELF_ENSEMBLE) + LEARNED
                    and not k[1].startswith("Bayer") and "learned" not in k[1]})
    learned = sorted({k[1] for p in psnr.values() for k in p
                      if k[0] == "net" and k[2] == 0 and "learned" in k[1] and k[1] not in LEARNED})
    for v in extra:
        rows.append((f"{v} - pinv", lambda p, v=v: diff(get(p, "net", v), get(p, "pinv"))))
        rows.append((f"{v} - lfnet-asp-n2", lambda p, v=v: diff(get(p, "net", v),
                                                                 get(p, "net", "lfnet-asp-n2"))))
    for v in learned:
        for base in ("lfnet-asp-n2", "lfnet-asp-n2-hard"):
            rows.append((f"{v} - {base}",
                         lambda p, v=v, base=base: diff(get(p, "net", v), get(p, "net", base))))
    colour = sorted({k[1] for p in psnr.values() for k in p
                     if k[0] == "net" and k[1].startswith("Bayer RGGB, ")
                     and k[1] not in (COLOUR, COLOUR + ", self-ensemble")})
    for v in colour:
        rows.append((f"colour {v[len('Bayer RGGB, '):]} - (pinv + better demosaic)",
                     lambda p, v=v: diff(get(p, "net", v), best_colour_pinv(p))))
    return rows


def table(psnr, role, which):
    lfs = sorted(lf for lf in psnr if role[lf] == which)
    out = [f"### {which} ({len(lfs)} light fields)", "",
           "| margin, dB | worst | " + " | ".join(lfs) + " |",
           "|---|---:|" + "---:|" * len(lfs)]
    for label, f in rows_of(psnr):
        vals = [f(psnr[lf]) for lf in lfs]
        have = [v for v in vals if v is not None]
        if not have:
            continue
        cells = ["" if v is None else f"{v:+.2f}" for v in vals]
        out.append(f"| {label} | {min(have):+.2f} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def main():
    path = sys.argv[1] if len(sys.argv) > 1 else "results/holdout/records.jsonl"
    psnr, role = load(path)
    for which in ("validation", "test"):
        print(table(psnr, role, which))


if __name__ == "__main__":
    main()
