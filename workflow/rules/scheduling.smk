# How Snakemake schedules local runs: without its job-rate limiter.

import sys


def lift_job_rate_limit():
    """Drop Snakemake's job-rate limiter (CLI default 100 jobs per 1 s) for local runs, which start at most --cores
    jobs at once, so it has nothing to limit. In Snakemake 9 each job-selection pass that leaves jobs waiting starts a
    timer for one more pass, and none is ever cancelled: timers pile up, one per job event, each pass stat-ing every
    input of every ready job. On the full set (3,277 jobs, ~1,000 ready for 2 cores) Snakemake held 52% of a core;
    the last timer also holds the process for one span after the last job. Snakemake's API runs without the limiter
    by default. Cluster runs keep it: there it paces submissions."""
    if not workflow.local_exec:
        return
    if not hasattr(workflow.scheduler, "job_rate_limiter"):
        sys.exit("error: this Snakemake's JobScheduler has no job_rate_limiter; update workflow/rules/scheduling.smk")
    workflow.scheduler.job_rate_limiter = None


onstart:
    lift_job_rate_limit()
