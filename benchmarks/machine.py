"""What every benchmark records about the machine it ran on (and the shipped networks it ran), so results from
different runs can be compared, and how it writes them."""

from __future__ import annotations

import json
import os
import platform
from pathlib import Path
from typing import Any

from refinenet.atomic import write_text


def machine_info(**extra: Any) -> dict[str, Any]:
    """CPU model, usable cores, memory, Python and the 1-minute load average at the call, plus `extra` fields."""
    cpu = platform.processor()
    if Path("/proc/cpuinfo").exists():
        names = [ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                 if ln.startswith("model name")]
        cpu = names[0] if names else cpu
    pages, page_size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    return {
        "cpu": cpu, "cores": len(os.sched_getaffinity(0)), "memory_gb": round(pages * page_size / 2**30, 1),
        "platform": platform.platform(), "python": platform.python_version(),
        "load_average_1min": os.getloadavg()[0], **extra,
    }


def shipped_networks(release) -> dict[str, str]:
    """The release that ran, as its model card names it: profile and fingerprint (params and training clouds)."""
    return {k: release.card[k] for k in ("profile", "fingerprint")}


def write_results(out: Path, stem: str, record: dict[str, Any], markdown: str) -> None:
    """`stem`.json (the record) and `stem`.md (its report) under `out`, each written whole."""
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / f"{stem}.json", json.dumps(record, indent=2) + "\n")
    write_text(out / f"{stem}.md", markdown)
