#!/usr/bin/env python3
"""Export the LPIPS-VGG weights hashcc needs, as one .npy per tensor (run once, needs internet).

    pip install torch torchvision numpy        # plus, optionally: pip install lpips
    python3 tools/export_lpips_weights.py OUT_DIR [--lin PATH]

Writes into OUT_DIR (the folder given to hashcc, which checks it with lpips_available()):
  features.{0,2,5,7,10,12,14,17,19,21,24,26,28}.{weight,bias}.npy
      torchvision vgg16 ImageNet weights (IMAGENET1K_V1, the ones LPIPS uses), float32,
      shapes (out, in, 3, 3) and (out,)
  vgg.lin{0..4}.model.1.weight.npy
      the LPIPS v0.1 linear heads, float32, shape (1, C, 1, 1), C = 64, 128, 256, 512, 512

--lin is where the linear heads come from: a folder of vgg.lin*.npy files (for example the
project's data/lpips/weights/v0.1_npy), or a vgg.pth file from richzhang/PerceptualSimilarity
(lpips/weights/v0.1/vgg.pth). Without --lin the installed `lpips` package's vgg.pth is used.
"""
import argparse
import os
import shutil
import sys

import numpy as np


def save(out_dir, name, tensor):
    a = np.ascontiguousarray(tensor.detach().cpu().numpy().astype("<f4"))
    np.save(os.path.join(out_dir, name), a)  # np.save appends nothing: name already ends in .npy
    print(f"  {name:34s} {tuple(a.shape)}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_dir")
    ap.add_argument("--lin", help="folder of vgg.lin*.npy or a vgg.pth (default: the lpips package's)")
    args = ap.parse_args()
    import torch
    import torchvision

    os.makedirs(args.out_dir, exist_ok=True)
    try:  # torchvision >= 0.13
        vgg = torchvision.models.vgg16(weights=torchvision.models.VGG16_Weights.IMAGENET1K_V1)
    except AttributeError:  # older torchvision
        vgg = torchvision.models.vgg16(pretrained=True)
    print("backbone: torchvision vgg16().features")
    for key, t in vgg.features.state_dict().items():  # keys "0.weight", "0.bias", ...
        idx = int(key.split(".")[0])
        if idx <= 28:  # up to conv5_3 (relu5_3 is index 29)
            save(args.out_dir, f"features.{key}.npy", t)

    print("linear heads: LPIPS v0.1 vgg")
    lin = args.lin
    if lin is None:
        try:
            import lpips
        except ImportError:
            sys.exit("no --lin given and the lpips package is not installed (pip install lpips)")
        lin = os.path.join(os.path.dirname(lpips.__file__), "weights", "v0.1", "vgg.pth")
    if os.path.isdir(lin):
        for k in range(5):
            name = f"vgg.lin{k}.model.1.weight.npy"
            shutil.copyfile(os.path.join(lin, name), os.path.join(args.out_dir, name))
            print(f"  {name:34s} (copied)")
    else:
        sd = torch.load(lin, map_location="cpu")
        for k in range(5):
            save(args.out_dir, f"vgg.lin{k}.model.1.weight.npy", sd[f"lin{k}.model.1.weight"])
    print(f"done: {args.out_dir}")


if __name__ == "__main__":
    main()
