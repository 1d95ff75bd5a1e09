"""One module per benchmark section; each exposes ``bench_<section>(cfg, table, raw, ...)``."""
