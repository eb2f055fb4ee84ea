# %% [markdown]
# # benchtwin from a notebook
#
# Simulate a small bench on the twin, analyse it in memory (nothing is written), look at the
# calibration result as a table and a figure. Open it in Jupyter as a notebook (jupytext, or VS Code's
# `# %%` cells), or run it as a script: `python docs/examples/notebook.py`. The test suite runs it
# (tests/app/test_notebook_example.py). The API: docs/api.md.

# %%
import benchtwin

# The embedded Jia 2019 scenario, made small: fewer probe stops, 24 CCD frames of 1024 × 768 px (the
# eccentricity fit of order 10 needs at least 24), an 8-face polygon. Units are in the values.
sc = benchtwin.load_scenario(None).with_overrides({
    "procedure.radial_reps": 2,
    "procedure.radial_positions": 24,
    "procedure.ccd_step": "15 deg",
    "bench.polygon_faces": 8,
    "instruments.ccd.width": "1024 px",
    "instruments.ccd.height": "768 px",
})
sc  # noqa: B018 - a notebook shows the cell's last value

# %%
# The twin writes the dataset into a temporary folder, removed when `ds` is no longer used
# (benchtwin.simulate(sc, keep=True) keeps it; benchtwin.simulate(sc, "folder") writes it there).
ds = benchtwin.simulate(sc, progress=False, backend="analytic")
ds  # noqa: B018

# %%
# The one analysis pipeline, in memory: a typed Results, no report and no results.json written.
r = benchtwin.analyze(ds, progress=False)
print(r)
print("eccentricity e =", r.eccentricity, "; θ0 =", r.theta0)
print("identified effects:", r.effect_names or "none")

# %%
# The calibration curve a certificate states: the encoder error at each calibrated angle with u,
# U = k·u and k (what u includes: r.calibration.u_includes).
df = r.to_dataframe()
print(df.to_string(index=False))

# %%
# The same as a figure (a matplotlib Figure: a notebook shows it; fig.savefig("curve.png") writes it).
fig = benchtwin.figure_error_curve(r)
fig  # noqa: B018

# %%
ds.cleanup()   # the temporary folder goes now rather than when `ds` is collected
