"""Tools that build and drive predictors outside a run: the contract check (``bench
check``), latency (``bench latency``), tuning (``bench tune``) and the paper's figures."""
