"""The report page as a visitor sees it: headless Chromium opens reports/index.html of a finished run from the file
system, checks that every image on it loaded (the page's own check, `data-missing-images`), and saves the first
screens as benchmarks/results/main_page.png (256 colours, so that the committed picture stays small).

    python benchmarks/page_screenshot.py RUN_DIR      # after `bash scripts/run.sh` in RUN_DIR
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image

RESULT = Path(__file__).resolve().parent / "results" / "main_page.png"
WIDTH, HEIGHT = 1280, 2000


def chromium() -> str:
    found = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None)
    if found is None:
        sys.exit("error: Chromium not found (Debian: apt-get install chromium)")
    return found


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="the repository folder of a finished run")
    parser.add_argument("--out", type=Path, default=RESULT)
    args = parser.parse_args()
    page = (args.run / "reports" / "index.html").resolve()
    if not page.is_file():
        sys.exit(f"error: {page}: no report page (run the main job first)")
    common = [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
              "--virtual-time-budget=10000"]
    dom = subprocess.run([*common, "--dump-dom", page.as_uri()], capture_output=True, text=True, check=True).stdout
    missing = re.search(r'data-missing-images="(\d+)"', dom)
    if missing is None or missing.group(1) != "0":
        sys.exit(f"error: {page}: {missing.group(1) if missing else 'unknown'} image(s) did not load")
    with tempfile.TemporaryDirectory() as scratch:
        shot = Path(scratch) / "page.png"
        subprocess.run([*common, f"--window-size={WIDTH},{HEIGHT}", f"--screenshot={shot}", page.as_uri()],
                       capture_output=True, check=True)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        Image.open(shot).convert("RGB").quantize(256).save(args.out, optimize=True)
    print(f"{args.out}: every image of {page} loaded; {args.out.stat().st_size / 1e3:.0f} kB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
