"""The significance thresholds and bench constants of the tracing (docs/effects.md justifies each).

χ² and F tests at ``P_SIG`` / ``F_SIG`` = 1e-3; a candidate's joint z ≥ ``Z_GATE`` = 4 and ΔBIC ≥
``DBIC_GATE`` = 10 ("very strong", Kass & Raftery 1995, J. Am. Stat. Assoc. 90, 773); ambiguity below
``AMBIG_DBIC`` = 6 with predictions' cos² > ``COLLINEAR``; ties within ``TIE_REL`` of the χ² scale.
The bench constants (``SPHERE_FORM_UM``: Jia et al. 2019 sec. 4.1) say where their numbers come from.
"""

# the async-motion estimator's constants (analysis/radial_motion.py), re-exported
from ..radial_motion import ASYNC_BAND as ASYNC_BAND
from ..radial_motion import ASYNC_NOISE_ORDER as ASYNC_NOISE_ORDER
from ..radial_motion import ASYNC_P as ASYNC_P

P_SIG = 1e-3        # χ² tests (residual before/after, nested signature tests)
#: a measured regressor moved beyond its u at this level (but within P_SIG's gate) keeps the
#: candidate and puts beside it what the moved regressor could stand for (selection.
#: _division_error_alternative): the conventional 5 % level of doubt, not of refusal
P_DOUBT = 0.05
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
#: readings is unmeasured and enters the model's uncertainty as one random offset per stop position
#: and polygon rep (nuisance columns), counted only if the probes' rep-to-rep scatter exceeds their
#: noise at p < ASYNC_P (F test). The estimator and its constants are the radial motion's
#: (analysis/radial_motion.py, RadialMotion.async_rms), imported above.
#: Two effects fitted together whose contributions are nearly collinear (cos² > COLLINEAR), of
#: opposite sign and each more than 1/DEGENERATE_RATIO times larger than their sum explain only a
#: small difference with two large terms: a degenerate pair (e.g. +105 % on the eccentricity term and
#: −105 % on the whole model for 0.05″ of ∫δY). Physical pairs may cancel partly — a wrong ∫δY term
#: against the tilt-extrapolated motion, 3:1 — and are not rejected for it.
DEGENERATE_RATIO = 0.1
#: Highest harmonic of θ the residual's harmonic test and the harmonic candidates (graduation_error's
#: significant orders) reach, capped further by the sampling ((distinct stop positions − 1)/2). The
#: analysis's own bound on a smooth axis motion: the radial motion is a series to ASYNC_NOISE_ORDER
#: (40) before its residual counts as probe noise, and δX is taken up to that order (X_ORDERS_MAX).
#: Cut at 20, a shift-angle design that resolves far more (0…14°: 345 positions) left the orders
#: 21…40 of the encoder error outside every candidate: on the twin's base benches (loop validation
#: seeds 660-663, truth: α less the base model, per stop) the ball bearings' −δX/r there is
#: 0.11…0.29″ RMS against a 0.07…0.09″ u per reading, the bench's χ²/dof after harmonics 1…20 was
#: 2.2…10.6, and the loop ended "unexplained" with no effect hidden. Above 40 the truth holds
#: 0.01…0.03″ RMS.
KMAX = ASYNC_NOISE_ORDER
#: Below this order the harmonic test takes every order under the Nyquist of the stop positions
#: ((P − 1)/2), as it did before KMAX reached 40; above it only where the positions leave redundancy
#: for each order ((P − 1)/3: tracing/evidence.py ``Evidence.kmax``).
KMAX_NYQUIST = 20
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
