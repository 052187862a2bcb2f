#!/usr/bin/env python3
"""Exported lfnet models on a GPU: correctness against the CPU, reconstruction and training times.

Needs only PyTorch (no lfnet build), so it runs on any machine whose Python has a CUDA torch.

    scripts/gpu-check.py prepare --lf DIR --model A.pt [--model B.pt ...] --out DIR
        (on the machine with lfnet) copies the light field's PNG views (DIR/views) and the
        exported models (lfnet export), so that DIR alone travels to the GPU machine.
    scripts/gpu-check.py run DIR --json OUT.json [--device cuda] [--repeats 5]
        times every model in DIR on the device (and checks it against the device's CPU).
    scripts/gpu-check.py table OUT.json [OUT2.json ...]
        prints the records as a Markdown table (docs/performance.md, "On a GPU").

Reconstruction: an exported model's `reconstruct` (docs/export.md) on the sensor image that its
own `simulate` makes of the light field, noiseless, timed after warm-up runs with the device
synchronised; PSNR against the light field, and the largest difference from the same call on
the CPU. Training: Adam steps of the whole net (MSE against the light field) on random crops
(the lfnet architecture) or patches (the paper's), in float32.
"""

import argparse
import glob
import json
import math
import os
import shutil
import statistics
import sys
import time

import torch


def grey_views(folder):
    """The views of a light-field folder as (U, V, H, W) floats in [0, 1], Rec. 601 luma."""
    from PIL import Image
    import numpy as np

    files = sorted(f for f in glob.glob(os.path.join(folder, "*.png")) if not os.path.basename(f).startswith("."))
    if not files:
        sys.exit(f"gpu-check: no PNG views in {folder}")
    side = int(round(math.sqrt(len(files))))
    if side * side != len(files):
        sys.exit(f"gpu-check: {len(files)} views in {folder} do not make a square grid")
    views = []
    for f in files:
        a = np.asarray(Image.open(f).convert("RGB"), dtype=np.float64) / 255.0
        views.append(0.299 * a[..., 0] + 0.587 * a[..., 1] + 0.114 * a[..., 2])
    lf = torch.from_numpy(np.stack(views)).float()
    return lf.view(side, side, lf.shape[1], lf.shape[2])


def prepare(args):
    views = os.path.join(args.out, "views")
    os.makedirs(views, exist_ok=True)
    lf = grey_views(args.lf)  # checks the folder
    for f in sorted(glob.glob(os.path.join(args.lf, "*.png"))):
        shutil.copy(f, views)
    with open(os.path.join(args.out, "source.txt"), "w") as f:
        f.write(os.path.basename(os.path.normpath(args.lf)) + "\n")
    for m in args.model:
        shutil.copy(m, os.path.join(args.out, os.path.basename(m)))
    print(f"gpu-check: {tuple(lf.shape)} light field and {len(args.model)} model(s) in {args.out}")


def sync(device):
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def timed(fn, device, repeats, warmup=2):
    """Median seconds of `repeats` calls after `warmup` calls, and the last result."""
    out = None
    for _ in range(warmup):
        out = fn()
    sync(device)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        sync(device)
        times.append(time.perf_counter() - start)
    return statistics.median(times), out


def psnr(a, b):
    mse = float(((a.float() - b.float()) ** 2).mean())
    return 10 * math.log10(1.0 / mse) if mse > 0 else float("inf")


def is_image_model(model):
    return hasattr(model, "multiple")


def reconstruct_cases(model, image):
    """(name, call) pairs: the reconstructions to time, as the model's reconstruct takes them."""
    if image:
        # Tiles of 256 (lfnet's default, bounded memory) and one tile over the whole image; the
        # self-ensemble's first two passes (asp:2: the image and its left-right mirror,
        # docs/export.md).
        def two_passes(s):
            one = model.reconstruct(s, 8192, False, 0.0)
            two = model.reconstruct(s.flip(2), 8192, False, 0.0).flip([1, 3])
            return ((one + two) / 2).clamp(0.0, 1.0)
        return [("tile 256", lambda s: model.reconstruct(s, 256, True, 0.0)),
                ("one tile", lambda s: model.reconstruct(s, 8192, True, 0.0)),
                ("two passes, one tile", two_passes)]
    return [("stride 5, batch 2048", lambda s: model.reconstruct(s, 5, 2048, False, True)),
            ("stride 5, batch 65536", lambda s: model.reconstruct(s, 5, 65536, False, True)),
            ("stride 2, batch 65536", lambda s: model.reconstruct(s, 2, 65536, False, True))]


def train_steps(model, image, lf, sensor, device, steps, batch):
    """Seconds per Adam step of the whole net in float32, and samples per second."""
    module = model  # trained in place: call this after the reconstructions
    for p in module.parameters():
        p.requires_grad_(True)
    opt = torch.optim.Adam([p for p in module.parameters()], lr=1e-4)
    U, V, H, W = lf.shape
    gen = torch.Generator().manual_seed(0)
    if image:
        crop = 128
        ys = torch.randint(0, (H - crop) // 2, (batch,), generator=gen) * 2
        xs = torch.randint(0, (W - crop) // 2, (batch,), generator=gen) * 2
        x = torch.stack([sensor[:, y:y + crop, x0:x0 + crop] for y, x0 in zip(ys.tolist(), xs.tolist())])
        t = torch.stack([lf[:, :, y:y + crop, x0:x0 + crop] for y, x0 in zip(ys.tolist(), xs.tolist())])
        # Every crop starts on an even pixel: the phase of asp:2 (period 1) is 0.
        run = lambda: module.forward(x, 0, 0.0)
    else:
        U_, V_, h, w = model.patch_shape
        ys = torch.randint(0, H - h, (batch,), generator=gen)
        xs = torch.randint(0, W - w, (batch,), generator=gen)
        x = torch.stack([sensor[:, y:y + h, x0:x0 + w].reshape(-1) for y, x0 in zip(ys.tolist(), xs.tolist())])
        t = torch.stack([lf[:, :, y:y + h, x0:x0 + w] for y, x0 in zip(ys.tolist(), xs.tolist())])
        run = lambda: module.forward(x, None)
    x, t = x.to(device), t.to(device).float()

    def step():
        opt.zero_grad(set_to_none=True)
        loss = torch.nn.functional.mse_loss(run().reshape(t.shape), t)
        loss.backward()
        opt.step()
        return loss

    seconds, _ = timed(step, device, steps, warmup=2)
    return seconds, batch / seconds


def run(args):
    device = torch.device(args.device)
    torch.backends.cudnn.benchmark = True
    if args.tf32 == "off":  # float32 products in full float32 (PyTorch's default allows TF32)
        torch.backends.cudnn.allow_tf32 = False
        torch.backends.cuda.matmul.allow_tf32 = False
    lf_cpu = grey_views(os.path.join(args.dir, "views"))
    if args.crop:
        lf_cpu = lf_cpu[:, :, :args.crop[0], :args.crop[1]].contiguous()
    if args.repeat_tiles:
        lf_cpu = lf_cpu.repeat(1, 1, *args.repeat_tiles).contiguous()
    source = open(os.path.join(args.dir, "source.txt")).read().strip()
    record = {
        "device": torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu",
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "tf32": args.tf32 if device.type == "cuda" else "n/a",
        "light_field": source,
        "size": list(lf_cpu.shape),
        "models": [],
    }
    print(f"gpu-check: {record['device']}, torch {record['torch']}, {record['light_field']} "
          f"{tuple(lf_cpu.shape)}", flush=True)
    for path in sorted(glob.glob(os.path.join(args.dir, "*.pt"))):
        name = os.path.basename(path)[:-3]
        if args.models and name not in args.models.split(","):
            continue
        cpu = torch.jit.load(path, map_location="cpu")
        image = is_image_model(cpu)
        with torch.no_grad():
            sensor_cpu = cpu.simulate(lf_cpu)
        entry = {"model": name, "architecture": "lfnet" if image else "paper", "cases": []}
        gpu = torch.jit.load(path, map_location=device)
        sensor = sensor_cpu.to(device)
        lf = lf_cpu.to(device)
        for i, ((case, call), (_, call_cpu)) in enumerate(zip(reconstruct_cases(gpu, image),
                                                              reconstruct_cases(cpu, image))):
            with torch.no_grad():
                seconds, out = timed(lambda: call(sensor), device, args.repeats)
                rec = {"case": case, "precision": "float32", "seconds": seconds,
                       "psnr": psnr(out, lf)}
                if args.compare_cpu and i == 0 and image:  # the CPU is slow: lfnet, first case
                    ref = call_cpu(sensor_cpu)
                    rec["max_diff_cpu"] = float((out.cpu() - ref).abs().max())
                    rec["psnr_cpu"] = psnr(ref, lf_cpu)
                if image and device.type == "cuda":
                    # bfloat16 through autocast: the convolutions in bfloat16, the rest float32.
                    def bf16():
                        with torch.autocast("cuda", dtype=torch.bfloat16):
                            return call(sensor)
                    try:
                        s16, o16 = timed(bf16, device, args.repeats)
                        rec["bf16_seconds"] = s16
                        rec["bf16_psnr"] = psnr(o16, lf)
                    except Exception as e:  # autocast of a TorchScript module may be refused
                        rec["bf16_error"] = str(e).splitlines()[0][:200]
            entry["cases"].append(rec)
            print(f"  {name} {case}: {rec}", flush=True)
        try:
            batch = args.train_batch if image else 2048
            seconds, rate = train_steps(gpu, image, lf_cpu, sensor_cpu, device, args.train_steps,
                                        batch)
            entry["train"] = {"batch": batch,
                              "sample": "128 x 128 crops" if image else "patches",
                              "seconds_per_step": seconds, "samples_per_second": rate}
        except Exception as e:
            entry["train"] = {"error": str(e).splitlines()[0][:200]}
        print(f"  {name} train: {entry['train']}", flush=True)
        record["models"].append(entry)
    with open(args.json, "w") as f:
        json.dump(record, f, indent=1)
    print(f"gpu-check: wrote {args.json}")


def table(args):
    print("| device | image | TF32 | model | case | float32 s | PSNR dB | bf16 s | bf16 PSNR dB | "
          "max diff vs CPU | train samples/s |")
    print("|---|---|---|---|---|---:|---:|---:|---:|---:|---:|")
    for path in args.json:
        r = json.load(open(path))
        for m in r["models"]:
            train = m.get("train", {})
            rate = (f"{train['samples_per_second']:.0f} ({train['sample']}, batch {train['batch']})"
                    if "samples_per_second" in train else "—")
            for i, c in enumerate(m["cases"]):
                bf = f"{c['bf16_seconds']:.4f}" if "bf16_seconds" in c else "—"
                bfp = f"{c['bf16_psnr']:.2f}" if "bf16_psnr" in c else "—"
                diff = f"{c['max_diff_cpu']:.1e}" if "max_diff_cpu" in c else "—"
                size = f"{r['size'][2]} x {r['size'][3]}"
                print(f"| {r['device']} | {size} | {r.get('tf32', 'on')} | {m['model']} | {c['case']} | {c['seconds']:.4f} | "
                      f"{c['psnr']:.2f} | {bf} | {bfp} | {diff} | {rate if i == 0 else ''} |")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("prepare")
    p.add_argument("--lf", required=True)
    p.add_argument("--model", action="append", required=True)
    p.add_argument("--out", required=True)
    r = sub.add_parser("run")
    r.add_argument("dir")
    r.add_argument("--json", required=True)
    r.add_argument("--device", default="cuda")
    r.add_argument("--repeats", type=int, default=5)
    r.add_argument("--train-steps", type=int, default=10)
    r.add_argument("--no-compare-cpu", dest="compare_cpu", action="store_false")
    r.add_argument("--tf32", choices=["on", "off"], default="on",
                   help="TF32 in float32 convolutions and products (PyTorch's default: on)")
    r.add_argument("--repeat-tiles", type=int, nargs=2, metavar=("R", "C"),
                   help="the light field tiled R x C times: a larger image to time")
    r.add_argument("--train-batch", type=int, default=16, help="crops per lfnet training step")
    r.add_argument("--models", default="", help="comma-separated model names (default: all)")
    r.add_argument("--crop", type=int, nargs=2, metavar=("H", "W"),
                   help="the top-left H x W pixels only (a quick check of the script)")
    t = sub.add_parser("table")
    t.add_argument("json", nargs="+")
    args = parser.parse_args()
    {"prepare": prepare, "run": run, "table": table}[args.command](args)


if __name__ == "__main__":
    main()
