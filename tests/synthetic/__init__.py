"""Test-only generators of synthetic data with known, injected effects (issue 16: nothing in
benchtwin/, twin/ or analysis/ imports them; tests/test_layering.py checks it).

- ``evidence``: tracing Evidence of a Jia/Hsieh bench with effects injected by their physics;
- ``polygon``: polygon readings from Hsieh et al. 2022 eq. 3.
"""
