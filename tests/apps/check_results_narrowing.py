"""Checks how scripts/results.py narrows a run: ONLY_LF picks light-field folders, and the
records made then replace only those of the same variant and light field. Prints "ok"."""
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
import results  # noqa: E402

tmp = tempfile.mkdtemp()
for name in ["val-a", "val-b", "test-a"]:
    os.makedirs(os.path.join(tmp, name))
    open(os.path.join(tmp, name, "set.json"), "w").write("{}")
os.makedirs(os.path.join(tmp, "val-c"))  # no set.json: never a light field
spec = {"dirs": [os.path.join(tmp, "val-*"), os.path.join(tmp, "test-*")], "with": "set.json"}
names = lambda: [os.path.basename(d) for d in results.values(spec, {}, "t")]
os.environ.pop("ONLY_LF", None)
assert names() == ["val-a", "val-b", "test-a"], names()
os.environ["ONLY_LF"] = "val-b test-a"
assert names() == ["val-b", "test-a"], names()


def write(path, rows):
    with open(path, "w") as f:
        f.writelines(json.dumps({"variant": v, "light_field": lf, "psnr_db": p}) + "\n"
                     for v, lf, p in rows)


def read(path):
    return sorted((r["variant"], r["light_field"], r["psnr_db"])
                  for r in map(json.loads, open(path)))


old, new = os.path.join(tmp, "old.jsonl"), os.path.join(tmp, "new.jsonl")
rows = [("m", "val-a", 1), ("m", "val-b", 2), ("k", "val-b", 3)]
write(new, [("m", "val-b", 9)])
write(old, rows)
results.replace_variants(old, new, light_fields=True)
assert read(old) == sorted([("m", "val-a", 1), ("m", "val-b", 9), ("k", "val-b", 3)]), read(old)
write(old, rows)
results.replace_variants(old, new)  # a whole variant
assert read(old) == sorted([("m", "val-b", 9), ("k", "val-b", 3)]), read(old)
print("ok")
