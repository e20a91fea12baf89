"""Thin entry points, one per Snakemake rule: parse explicit paths and parameters, call the library,
write outputs atomically. No algorithm code lives here."""
