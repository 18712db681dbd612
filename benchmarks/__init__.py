"""The benchmarks of torch_eigview: scripts run from the repository root, never installed.

Each ``bench_*.py`` is run as ``python benchmarks/bench_<name>.py [--quick] [--out FILE]``
and writes one result record (``_record.py``) that ``docs/make_pages.py`` renders into
``docs/benchmarks.md``. The folder is a package so that the scripts, their helpers and
their tests import each other as ``benchmarks.<module>`` under pytest and when run.
"""
