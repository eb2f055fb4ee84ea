"""The significance thresholds and bench constants of the tracing (docs/effects.md justifies each).

χ² and F tests at ``P_SIG`` / ``F_SIG`` = 1e-3; a candidate's joint z ≥ ``Z_GATE`` = 4 and ΔBIC ≥
``DBIC_GATE`` = 10 ("very strong", Kass & Raftery 1995, J. Am. Stat. Assoc. 90, 773); ambiguity below
``AMBIG_DBIC`` = 6 with predictions' cos² > ``COLLINEAR``; ties within ``TIE_REL`` of the χ² scale.
The bench constants (``SPHERE_FORM_UM``: Jia et al. 2019 sec. 4.1) say where their numbers come from.
"""

P_SIG = 1e-3        # χ² tests (residual before/after, nested signature tests)
Z_GATE = 4.0        # a candidate's parameters must be ≥ 4 standard uncertainties from zero (jointly)
DBIC_GATE = 10.0    # ... and lower the BIC by ≥ 10 ("very strong" on Kass & Raftery's scale)
AMBIG_DBIC = 6.0    # candidates within 6 BIC units (less than "strong" evidence, Kass & Raftery) ...
COLLINEAR = 0.9     # ... whose predictions have cos² > 0.9 cannot be told apart
Z_PAIR = 2.0        # a pair is tried only if one of its members alone reaches z ≥ 2 (saves fits on nulls)
MAX_CV_FOLDS = 12
F_SIG = 1e-3        # F-test of a candidate's χ² improvement against the residual scatter it leaves
#: practical significance: each effect of a candidate must change the readings by at least this share
#: of the noise floor (the combined standard uncertainty u_c of one α, GUM type A and B; RMS over the
#: polygon readings). Every real bench has declared imperfections below u_c that 500 readings resolve
#: statistically (the autocollimator's accuracy curve within its class is a gain of ~5e-4 on α,
#: 0.024″ RMS; the spheres' 0.014 µm form read as motion, ~0.04″): they change no calibrated value
#: beyond its uncertainty and are not findings. The same bound applies to "is there anything to
#: explain?" (the residual's RMS beyond the uncertainties, u·√(χ²/ν − 1)).
SIZE_GATE = 0.5
#: Test-sphere form not measured by the analysis: Jia sec. 4.1 quotes the spheres' max roughness,
#: 0.014 µm. A form of that size is read as motion by eq. 7 (orders 2…10 kept), so the model's ∫δY
#: term carries it; it enters the model's uncertainty (type B) as nuisance columns with a
#: rectangular distribution within ±0.014 µm per Fourier coefficient (u = 0.014/√3 µm).
SPHERE_FORM_UM = 0.014
#: Non-repeating (asynchronous) motion of the axis: its part along X at the time of the polygon
#: readings is unmeasured (the probes run in other revolutions) and reads −δX_async/r. Its size is
#: known from the probes' rep-to-rep scatter (isotropic: the same along X as along Y); it enters the
#: model's uncertainty as one random offset per stop position and polygon rep (nuisance columns),
#: counted only if the scatter exceeds the probes' noise at p < ASYNC_P (F test).
ASYNC_P = 0.01
ASYNC_NOISE_ORDER = 40
ASYNC_BAND = 10
#: Two effects fitted together whose contributions are nearly collinear (cos² > COLLINEAR), of
#: opposite sign and each more than 1/DEGENERATE_RATIO times larger than their sum explain only a
#: small difference with two large terms: a degenerate pair (e.g. +105 % on the eccentricity term and
#: −105 % on the whole model for 0.05″ of ∫δY). Physical pairs may cancel partly — a wrong ∫δY term
#: against the tilt-extrapolated motion, 3:1 — and are not rejected for it.
DEGENERATE_RATIO = 0.1
THETA_BIN_DEG = 0.05  # readings closer than this in θ count as one stop position (harmonic Nyquist, cells)
#: Ties. Two information criteria (BIC, AICc, held-out χ²) closer than TIE_REL × the scale of the
#: problem's χ² (max(χ² of no effect, number of rows)) are equal: the comparison is decided by the
#: stated preference of :func:`_prefer` instead of by rounding. Why 1e-6: the χ² of a least-squares
#: fit on unit-norm columns carries a rounding error of ~κ·ε·χ² (ε = 2.2e-16; κ ≤ ~1e4 for these
#: designs after column scaling, columns worse than 1e-8 in rank are dropped), so ~1e-12 relative,
#: and another BLAS kernel (OpenBLAS Prescott / Haswell / SkylakeX) reorders sums at that level; 1e-6
#: is six orders above it. On the other side 1e-6 × χ² is ~1e-3 BIC units for n ≈ 1000 readings,
#: three orders below the smallest difference read as evidence (2 units: "not worth more than a bare
#: mention", Kass & Raftery 1995). Exactly collinear candidates (a sphere form read as motion and a
#: division error at the same harmonics: the same column space) are the tie this settles.
TIE_REL = 1e-6
