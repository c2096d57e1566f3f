"""The analysis: the Parquet ``tables``, scene-level statistics (``stats``), figures
(``plots``, ``render``), the HTML ``report``, the paper's ``claims``, ``compare`` of two
runs and ``robustness`` against drawn users."""
