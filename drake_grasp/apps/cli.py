"""Small helpers shared by the command-line entry points."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses as dc
import functools
import json
import os
import signal
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from drake_grasp.datasets.shards import JobFailure, run_shards
from drake_grasp.robot.log import program_logging  # noqa: F401  (the programs import it from here)
from drake_grasp.simulation.divergence import first_line

LISTED_OBJECTS = 8  # names a note lists

if TYPE_CHECKING:
    import torch

    from drake_grasp.datasets.grasp_data import GraspDataset
    from drake_grasp.policy.config import SelectionConfig
    from drake_grasp.simulation.objects import ObjectModel


def fail(error: Exception | str) -> int:
    """Prints a one-line error naming the problem; returns the CLI exit code 2."""
    print(f"error: {first_line(error)}", file=sys.stderr)
    return 2


def failed_run_line(name: str, failure: JobFailure) -> str:
    """One log line naming a run that raised, and its error."""
    return f"{name}: failed: {type(failure.error).__name__}: {first_line(failure.error)}"


@contextlib.contextmanager
def sigterm_interrupts() -> Iterator[None]:
    """Within the block SIGTERM (`kill`, a batch scheduler's stop, a background job's only stop: a
    shell starts those with Ctrl-C ignored) interrupts like Ctrl-C, so that a long job stopped either
    way keeps and reports what it finished."""

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def positive_float(text: str) -> float:
    value = float(text)
    if not value > 0.0:  # (NaN too)
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def non_negative_int(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be zero or positive, got {text}")
    return value


def fraction(text: str) -> float:
    value = float(text)
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"must lie strictly between 0 and 1, got {text}")
    return value


def score_threshold(text: str) -> float:
    """A threshold on a score in [0, 1): 0 turns it off."""
    value = float(text)
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"must lie in [0, 1) (0: off), got {text}")
    return value


def write_report_pair(out: Path | None, result: dict, text: str) -> None:
    """OUT.json (`result`) and OUT.md (`text`), unless `out` is None; `text` printed either way.
    The extensions are appended (an OUT with a dot, `offset_0.01`, keeps its whole name)."""
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.with_name(out.name + ".json").write_text(json.dumps(result, indent=1))
        out.with_name(out.name + ".md").write_text(text)
    print(text)


def out_folder(text: str) -> Path:
    """An `--out` folder: absent (it is made) or a folder, never an existing file."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a file; give a folder (or a path that does not exist)")
    return path


def out_file(text: str) -> Path:
    """An `--out` file or file prefix: not an existing folder, and not inside a file."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder; give a file name")
    blocking = next((p for p in path.parents if p.exists() and not p.is_dir()), None)
    if blocking is not None:
        raise argparse.ArgumentTypeError(f"{text} lies inside {blocking}, which is a file, not a folder")
    return path


def positive_ints(text: str) -> list[int]:
    """A comma-separated list of positive integers."""
    try:
        return [positive_int(item) for item in text.split(",")]
    except (ValueError, argparse.ArgumentTypeError):
        message = f"expected positive integers separated by commas, got {text!r}"
        raise argparse.ArgumentTypeError(message) from None


def shard_range(text: str) -> range:
    """`FIRST:STOP`, the shard indices FIRST, ..., STOP - 1 of a job."""
    try:
        first, stop = (int(part) for part in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected FIRST:STOP shard indices, got {text!r}") from None
    if not 0 <= first < stop:
        raise argparse.ArgumentTypeError(f"need 0 <= FIRST < STOP, got {text!r}")
    return range(first, stop)


def use_threads(threads: int | None) -> None:
    """Torch's intra-op threads set to `threads` (`--threads`); None or 0: torch's default (all cores)."""
    if threads:
        import torch

        torch.set_num_threads(threads)


def simulation_worker(workers: int) -> None:
    """A worker process's set-up, one of `workers` that each run simulations: Drake quiet, and torch's
    threads the machine's cores shared among the workers (at least one; `OMP_NUM_THREADS` overrides).
    Two runs side by side on two cores, each with torch on both, took 12-15 % longer than with one
    thread each, with the same attempts."""
    program_logging()
    if "OMP_NUM_THREADS" in os.environ:
        return
    threads = max(1, (os.cpu_count() or 1) // max(workers, 1))
    os.environ["OMP_NUM_THREADS"] = str(threads)  # (read when torch is imported)
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(threads)


def torch_device(name: str) -> torch.device:
    """The torch device called `name` (`--device`); ValueError when this machine has none."""
    import torch

    try:
        device = torch.device(name)
    except RuntimeError:
        raise ValueError(f"unknown torch device '{name}' (use 'cpu' or 'cuda')") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError("--device cuda: this machine has no CUDA GPU")
    return device


def add_hand_option(parser: argparse.ArgumentParser) -> None:
    """`--hand`: a shipped hand or a hand YAML file (default: the arm's, the Franka hand unless its file
    names another)."""
    from drake_grasp.robot.hand import known_hands

    parser.add_argument("--hand", default="", metavar="HAND",
                        help=f"one of {known_hands()} or a hand YAML file (default: the arm's hand)")


def add_sampler_option(parser: argparse.ArgumentParser, default: str | None) -> None:
    """`--sampler`: which candidates the policies rank (`SamplingConfig.sampler`; None: the scenario's)."""
    from drake_grasp.robot.task import SAMPLERS

    parser.add_argument("--sampler", choices=[s for s in SAMPLERS if s != "topdown"], default=default,
                        help="the grasp candidates: uniform (the paper's: random grasp points and "
                             "approaches), gpg (hand placements centred on the cloud, pushed in until they "
                             "would touch it: for objects as wide as the hand opens) or mixed (half of "
                             f"each) (default: {default or 'the scenario' + chr(39) + 's'})")


def add_selection_option(parser: argparse.ArgumentParser) -> None:
    """`--selection full|staged`, `--cnn-weights`, `--cnn-precision`, `--hold-weights` and
    `--hold-join-parts`: how the CNN policies use which CNN (`drake_grasp.policy.config`)."""
    from drake_grasp.policy.config import PRECISIONS

    parser.add_argument("--selection", choices=("full", "staged"), default="staged",
                        help="staged (default): the CNN scores neither the candidates whose open hand would "
                             "hit the observed cloud nor, for cnn_rp, those p_r keeps out of the top ranks "
                             "(5-6x faster, the same top ranks); full: every candidate, as the paper does")
    parser.add_argument("--cnn-weights", default=None,
                        help="the stability CNN of the cnn and cnn_rp policies (default "
                             "models/grasp_cnn_all.pt; models/grasp_cnn.pt: trained on the 8 blocks, "
                             "as the paper)")
    parser.add_argument("--cnn-precision", choices=PRECISIONS, default=None,
                        help="the stability CNN's arithmetic: bfloat16 is about twice as fast on a CPU with "
                             "native bfloat16 (AVX512-BF16, AMX), p_s within 0.005; auto (the default): "
                             "bfloat16 where native, else float32 (the closed loop's)")
    parser.add_argument("--hold-weights", default=None,
                        help="the hold predictor (train hold) with which the cnn and cnn_rp policies also "
                             "weigh whether the object will pivot out of the lift (default "
                             "models/grasp_hold.pt; 'none': p_s alone, as the paper)")
    parser.add_argument("--hold-join-parts", action=argparse.BooleanOptionalAction, default=None,
                        help="whether the hold predictor sees a part that continues a body end to end (the "
                             "neck or cap of a lying bottle or can, which the camera sees apart from the "
                             "body) as one object with it (default: yes; --no-hold-join-parts: the "
                             "camera's pieces as they are)")


def selection_config(args: argparse.Namespace) -> SelectionConfig:
    """Detection's `SelectionConfig` (`DetectConfig`'s: the programs that take these options detect grasps)
    with what `add_selection_option`'s options ask for."""
    from drake_grasp.cell.detection import DetectConfig

    chosen = {"staged": args.selection == "staged"}
    if args.cnn_weights is not None:
        chosen["cnn_weights"] = args.cnn_weights
    if args.cnn_precision is not None:
        chosen["cnn_precision"] = args.cnn_precision
    if args.hold_weights is not None:
        chosen["hold_weights"] = None if args.hold_weights.lower() == "none" else args.hold_weights
    if args.hold_join_parts is not None:
        chosen["hold_join_parts"] = args.hold_join_parts
    return dc.replace(DetectConfig().selection, **chosen)


def note_contact_fill(models: Sequence[ObjectModel]) -> None:
    """Says once what was changed to make a set's files ready (`ObjectModel.notes`: inertias recomputed,
    lengths read in millimetres) and which objects carry no Drake contact properties and get the
    project's (their models parsed once here, so Drake's parser warnings about them are summarised too)."""
    from pydrake.multibody.plant import AddMultibodyPlant
    from pydrake.systems.framework import DiagramBuilder

    from drake_grasp.robot.config import default_plant_config
    from drake_grasp.robot.contact_model import OBJECT_CONTACT
    from drake_grasp.robot.paths import make_parser
    from drake_grasp.robot.plant import add_scene

    notes: dict[str, list[str]] = {}
    for model in models:
        for note in model.notes:
            notes.setdefault(note.split(" of link ")[0] if note.startswith("inertia ") else note, []).append(
                model.name)
    for note, names in notes.items():
        listed = ", ".join(names[:LISTED_OBJECTS]) + (", ..." if len(names) > LISTED_OBJECTS else "")
        what = (f"an impossible {note} as the file gives it; recomputed from the collision pieces' hulls at "
                f"the file's mass" if note.startswith("inertia ") else note)
        print(f"note: {len(names)} of {len(models)} objects: {what}: {listed}", file=sys.stderr)
    plant, _ = AddMultibodyPlant(default_plant_config(), DiagramBuilder())
    filled = add_scene(plant, make_parser(plant), robot=None, objects=models).filled_contact
    if filled:
        listed = ", ".join(filled[:LISTED_OBJECTS]) + (", ..." if len(filled) > LISTED_OBJECTS else "")
        print(f"note: {len(filled)} of {len(models)} objects carry no Drake contact properties and get the "
              f"project's (compliant hydroelastic, {OBJECT_CONTACT.hydroelastic_modulus:g} Pa; friction "
              f"{OBJECT_CONTACT.friction} where the file gives none): {listed}", file=sys.stderr)


def add_job_options(parser: argparse.ArgumentParser) -> None:
    """The options every sharded collection job shares: its folder and seed, where it runs, which part."""
    parser.add_argument("--out", type=out_folder, required=True, help="folder of the shards")
    parser.add_argument("--seed", type=non_negative_int, default=0)
    parser.add_argument("--workers", type=positive_int, default=None, help="default: one per core")
    parser.add_argument("--ray-address", default=None,
                        help="run on a Ray cluster ('auto', 'ray://host:10001') instead of local workers")
    parser.add_argument("--shards", type=shard_range, default=None, metavar="FIRST:STOP",
                        help="compute only these shards of the job, to split it across machines "
                             "(copy the shard files into one folder afterwards)")


def collect_shards(shard: Callable[..., dict], job: dict, *, out_dir: Path, num_shards: int, shard_size: int,
                   unit: str, args: argparse.Namespace, rows_of: Callable[[int], int] | None = None) -> int:
    """Runs a labelled collection job's missing shards (`shard(k, **job)`); returns the CLI exit code.

    The progress bar counts rows and their positive rate (the shards' `label`);
    Ctrl-C or SIGTERM keeps the finished shards and says how to continue.
    """
    try:
        with sigterm_interrupts():
            run_shards(functools.partial(shard, **job), num_shards=num_shards, out_dir=out_dir,
                       workers=args.workers or 0, ray_address=args.ray_address, unit=unit,
                       shard_size=shard_size, worker_init=program_logging, only=args.shards, rows_of=rows_of,
                       progress_stats=lambda arrays: (len(arrays["label"]), int(arrays["label"].sum())))
    except (ValueError, RuntimeError) as e:
        return fail(e)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished shards are kept in {out_dir}; rerun the command to continue",
              file=sys.stderr)
        return 130
    print(f"{unit} in {out_dir}")
    return 0


def own_trials(data: GraspDataset, sampler: str, folders: list[Path], all_samplers: bool,
               doing: str) -> GraspDataset:
    """The trials of `folders` whose candidates the baseline's own sampler made (all of them with
    `all_samplers`, or where none are marked as its own)."""
    own = data.made_by(sampler)
    if len(own) == 0:
        print(f"note: {' '.join(map(str, folders))} hold no trials of the '{sampler}' sampler; the baseline "
              f"is meant for its own ('collect_grasps --sampler {sampler}'): {doing} all", file=sys.stderr)
        return data
    if len(own) < len(data) and not all_samplers:
        print(f"{doing} the {len(own)} of {len(data)} trials whose candidates the '{sampler}' sampler "
              "made (--all-samplers: all)", file=sys.stderr)
        return data.subset(own)
    return data
