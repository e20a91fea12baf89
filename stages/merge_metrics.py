"""Merge the per-table metrics files into reports/metrics.json, the file `dvc metrics show` reads."""

import argparse
import json
from pathlib import Path

from refinenet import stage
from refinenet.atomic import write_text
from refinenet.errors import InputError


def main(args: argparse.Namespace) -> None:
    merged = {}
    for path in map(Path, args.inputs):
        try:
            merged[path.stem] = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as err:
            raise InputError(path, f"unreadable metrics file ({err})") from None
    write_text(args.out, json.dumps(merged, indent=2) + "\n")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--inputs", nargs="+", required=True)
    parser.add_argument("--out", required=True)
    stage.run(parser, main)
