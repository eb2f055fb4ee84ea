"""Helpers shared by the test modules (issue 35): no test module imports another one.

- ``datasets``: the session's twin datasets, each scenario simulated once per run (the
  ``datasets`` fixture of tests/conftest.py);
- ``scenarios``: the small scenarios the twin tests simulate, and ``files`` (a folder's bytes);
- ``fake_dataset``: a small valid dataset written directly (no twin), and its manifest;
- ``bench_file``: a bench file's raw tables (hardware-in-the-loop and fuzz tests);
- ``poses``: bench poses built by hand (instrument and vibration tests);
- ``grating``: a supersampled renderer of radial grating images (Jia 2019 analysis tests);
- ``gl``: the one OpenGL skip marker;
- ``simlog``: an opt-in log of every twin simulation and process pool of a run;
- ``known_truth``: a hand-made truth folder of known values (the ``truth`` fixture of tests/app/conftest.py);
- ``fuzz``: the fuzz tests' settings, hostile values and mutated files;
- ``readers``: strict JSON and the example lab file (the strict-reader tests);
- ``study``: the study tests' counting stand-in point function and study files;
- ``resume``: the resume tests' small acquisition, injected full disk and dataset comparison
  (the ``simulated`` fixture of tests/hw/conftest.py).

tests/test_support_rules.py fails when a test module imports another.
"""
