"""``semmatch predict``: label a sequence with a trained network or the (noisy) oracle."""

from __future__ import annotations

import argparse


def register(sub) -> None:
    """Add ``semmatch predict``."""
    from semmatch.cli.common import add_output_flags, add_recording_options, number
    from semmatch.io.outputs import declare_paths

    p = sub.add_parser(
        "predict",
        help="write a labels folder for a sequence (network checkpoint, oracle or noisy oracle)",
        description="Label every frame of SEQ and write a labels folder (000000.png ...) to --out.",
    )
    p.add_argument("sequence", metavar="SEQ", help="sequence folder or recording (any registered layout)")
    add_recording_options(p)
    p.add_argument("--model", required=True,
                   help="checkpoint (.pt), 'oracle' (ground truth) or 'noisy:RATE' (noisy oracle, e.g. noisy:0.2)")
    p.add_argument("--out", required=True, help="labels folder to write")
    p.add_argument("--probs", action="store_true", help="also write probabilities to OUT/probs/*.npy (float16)")
    p.add_argument("--seed", type=number(int, lo=0), default=0, help="seed of the noisy oracle")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto", help="auto: CUDA when present")
    p.add_argument("--no-flip", action="store_true",
                   help="one network pass (default: the average with the mirror image, twice the time)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing labels folder semmatch wrote at --out (anything else is refused)")
    add_output_flags(p, json_what="where the labels went", quiet="the progress bar")
    declare_paths(p, inputs=("sequence", "model", "intrinsics"), outputs=("out",))
    p.set_defaults(func=run)


def make_segmenter(spec: str, *, seed: int = 0, device: str = "auto", flip: bool = True):
    """A segmenter from a ``--model`` value: checkpoint path, ``oracle`` or ``noisy:RATE``."""
    from semmatch.segment.oracle import NoisyOracle, OracleSegmenter

    if spec == "oracle":
        return OracleSegmenter()
    if spec.startswith("noisy:"):
        try:
            rate = float(spec.split(":", 1)[1])
        except ValueError:
            raise ValueError(f"--model {spec!r}: expected noisy:RATE with RATE a number in [0, 1]") from None
        return NoisyOracle(rate, seed=seed)
    from semmatch.segment import load_model

    return load_model(spec, device=None if device == "auto" else device, flip=flip)


def run(args: argparse.Namespace) -> int:
    """Predict and print where the labels went."""
    from semmatch.cli.common import emit, open_sequence
    from semmatch.segment import predict_sequence

    seq = open_sequence(args, args.sequence)
    if len(seq) == 0:
        raise ValueError(f"{args.sequence}: the sequence has no frames (poses.txt lists none); nothing to predict")
    model = make_segmenter(args.model, seed=args.seed, device=args.device, flip=not args.no_flip)
    out = predict_sequence(model, seq, args.out, probs=args.probs, progress=not args.quiet,
                           overwrite=args.overwrite, inputs=[args.sequence])
    name = getattr(model, "name", args.model)
    return emit({"out": str(out), "frames": len(seq), "model": name, "probs": args.probs}, args.json,
                f"{out}: {len(seq)} label images from {name}")
