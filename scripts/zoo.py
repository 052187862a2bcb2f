#!/usr/bin/python3
"""Writes the `measured` block of every card in models/zoo.json from the records under results/:
its margins over pinv on the light fields of the benchmark section that measured it (the
cross-scene benchmark for ASP N = 2, the other cameras' sections otherwise) with its seconds, and
its worst and mean margins over pinv on the validation and test sets (docs/protocol.md; the
validation mean ranks models for --budget). A card's
`measured_as.variant` names its records. Usage: scripts/zoo.py [--check]  (--check: exit 1 if
the file would change)."""
import json
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ZOO = os.path.join(ROOT, "models", "zoo.json")
SECTIONS = ["cross-scene", "other-phi", "colour", "learned-codes"]


def records(section):
    path = os.path.join(ROOT, "results", section, "records.jsonl")
    return [json.loads(l) for l in open(path) if l.strip()] if os.path.exists(path) else []


def same_camera(a, b):
    return a["phi"] == b["phi"] and a.get("cfa") == b.get("cfa")


def pinv_of(rs, r, own_camera):
    """PSNR of pinv on r's light field and noise (colour: the better demosaic), of r's own
    camera or of the ASP pair asp:2 (grey)."""
    best = None
    for o in rs:
        if (o["method"] == "pinv" and o["light_field"] == r["light_field"]
                and o.get("noise_sigma", 0) == r.get("noise_sigma", 0) and o["mode"] == r["mode"]
                and (same_camera(o, r) if own_camera else
                     (o.get("cfa") is None and r.get("cfa") is None and o["phi"]["name"] == "asp"
                      and o["phi"]["n"] == 2))):
            best = o["psnr_db"] if best is None else max(best, o["psnr_db"])
    return best


def margins(rs, variant):
    """Margins over pinv of the records of `variant` at noise 0, per light field: over its own
    camera's pinv where the records have it, else over asp:2's; and which it was."""
    own = [r for r in rs if r["method"] == "net" and r.get("variant") == variant
           and not r.get("noise_sigma")]
    for own_camera in (True, False):
        out, seconds = {}, []
        for r in own:
            p = pinv_of(rs, r, own_camera)
            if p is not None:
                out[r["light_field"]] = round(r["psnr_db"] - p, 2)
                seconds.append(r["seconds"])
        if out:
            return out, seconds, "its own camera's pinv" if own_camera else "pinv of asp:2"
    return {}, [], ""


def measure(card):
    variant = card.get("measured_as", {}).get("variant")
    if not variant:
        return None
    measured = {"command": "scripts/zoo.py"}
    for section in SECTIONS:
        m, seconds, over = margins(records(section), variant)
        if m:
            measured["benchmark"] = {"section": section, "over": over, "margins_over_pinv_db": m,
                                     "seconds": round(sum(seconds) / len(seconds), 2)}
            break
    hold = records("holdout")
    for role in ("validation", "test"):
        rs = [r for r in hold if r.get("set", {}).get("role") == role]
        m, _, over = margins(rs, variant)
        if m:
            worst = min(m, key=m.get)
            measured[role] = {"over": over, "worst_margin_over_pinv_db": m[worst],
                              "worst_light_field": worst,
                              "mean_margin_over_pinv_db": round(sum(m.values()) / len(m), 2),
                              "light_fields": len(m)}
    return measured


def main():
    zoo = json.load(open(ZOO))
    for card in zoo["models"]:
        m = measure(card)
        if m:
            card["measured"] = m
    text = "{\n  \"about\": " + json.dumps(zoo["about"]) + ",\n  \"models\": [\n"
    text += ",\n".join("    " + json.dumps(c) for c in zoo["models"]) + "\n  ]\n}\n"
    if "--check" in sys.argv:
        sys.exit(0 if open(ZOO).read() == text else 1)
    open(ZOO, "w").write(text)


if __name__ == "__main__":
    main()
