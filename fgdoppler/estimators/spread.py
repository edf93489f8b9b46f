r"""Covariances (and the smoother's point) where the likelihood is not Gaussian: posterior samples about an estimate.

The smoother reports the maximum a posteriori trajectory and, by default,
the Laplace covariance — the inverse Hessian of the cost at that optimum.
Where the likelihood of the track is a thin curved valley (far from the
baseline, near its ends) that covariance describes a straight ellipsoid
tangent to the valley, and the truth, somewhere along the curve, lies many
of its standard deviations away: measured on the paper's case a 5 km
(100 runs, seed 2026) a few ``ok`` smoothed tracks had a time-averaged NEES
of 50-350 while starting Levenberg–Marquardt from the truth converged to
the very same optimum — the estimate was right, its covariance was not.

This module widens the covariance there to enclose the posterior
mean-square error of the reported estimate,

.. math::

    \mathbf\Sigma_0 = \mathrm E\big[(\mathbf x_0 - \hat{\mathbf x}_0)(\mathbf x_0 - \hat{\mathbf x}_0)^\top
        \,\big|\, z_{1:N}\big],

estimated from samples of the first state's posterior under the
deterministic constant-velocity model (the process noise of these models
moves a 30 s track by metres; the particle estimator makes the same
approximation, :mod:`fgdoppler.estimators.particle`): importance sampling
from :math:`\mathcal N(\hat{\mathbf x}_0, 4\mathbf P_0)`, resampling, then
Metropolis moves that let the samples follow the valley.  What the samples
add is their departure from their own Gaussian model: the sampled cost's
Gauss–Newton information :math:`\mathbf I_\mathrm{cv}` (:func:`_information`)
gives :math:`\mathbf C = \mathbf I_\mathrm{cv}^{-1}`, and the excess
:math:`\mathbf E = \mathrm{encl}(\mathbf C, \mathbf\Sigma_0) - \mathbf C`
(:func:`_enclosing`: the samples only ever widen) is added to the
smoother's own Laplace marginals :math:`\mathbf P^\mathrm L_k`, carried
forward at constant velocity (:func:`_carried`):

.. math::

    \mathbf P_k = \mathbf P^\mathrm L_k + \mathbf F(t_k - t_0)\,\mathbf E\,\mathbf F(t_k - t_0)^\top
        \succeq \mathbf P^\mathrm L_k.

The Laplace marginals hold what the process noise lets the track do,
conditioned on the data; the samples, moving at exactly constant velocity,
do not, and measure only what the non-Gaussian likelihood adds.  Until
2026-11 the samples' matrix replaced the first state's and the process noise
was added unconditioned, :math:`\mathbf F\mathbf\Sigma_0\mathbf F^\top + \mathbf Q(t_k - t_0)`:
over a long recording that understated the first states where the process
noise has a share (case a 30 km, 90 s: :math:`\mathbf C` is 0.13-0.15 of
:math:`\mathbf P^\mathrm L_0` in one direction) and overstated the last,
the whole span's :math:`\mathbf Q` dominating the posterior's thin direction
(the same recording with a 30 s gap, 20 seeds: the smoother's last errors
along that direction 0.46 of its standard deviation, and every filter
``doubtful`` by the ``reference`` finding against it;
``studies/gap_reference_check.py``).

It runs only where the two-point curvature probe
(:mod:`fgdoppler.estimators.curvature`) finds the cost 3 standard
deviations along the covariance's major axis more than
:data:`SAMPLING_LIMIT` times off its quadratic model (either way): in the
well-observed scenarios, where the ratio is 1.1-1.7, the Laplace covariance
stands, unchanged.  The limit is below the verdict's
(:data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT`, 10) because
this is a correction, not an alarm: in case a 5 km (seed 2026) smoothed
tracks with ratios 6-7 had a time-averaged NEES of 55-78 with the Laplace
covariance and 34-44 with the sampled one.

Skewed valleys: the posterior mean
----------------------------------
Where the probe finds the cost near-quadratic within 3 standard deviations
the likelihood may still be long and lopsided beyond them (the paper's
25 km scenarios: position σ about 1.4 km along a valley that is steeper
on one side).  Then the maximum a posteriori track is not the best point:
the posterior mean is.  A cheap check decides: :data:`SAMPLES` draws from
:math:`\mathcal N(\hat{\mathbf x}_0, 4\mathbf P_0)`, importance-weighted
and resampled (no Metropolis moves: about 10 ms), give the shift
:math:`\mathbf d` of the posterior mean from the sampled posterior's mode
(which the estimate is, up to the process noise: "Where the process noise
matters" below); when its squared
Mahalanobis length in the Laplace covariance,
:math:`w = \mathbf d^\top\mathbf P_0^{-1}\mathbf d`, exceeds
:data:`MEAN_SHIFT_MIN`, the samples are moved (:data:`MOVES` sweeps), the
shift is measured again on them, and where it still exceeds that the
reported track is moved by it, the skew of the posterior,

.. math::

    \bar{\mathbf x}_k = \hat{\mathbf x}_k + \mathbf F(t_k - t_0)\,(\bar{\mathbf x}_0 - \tilde{\mathbf x}_0),

with :math:`\bar{\mathbf x}_0` the moved samples' mean and
:math:`\tilde{\mathbf x}_0` their mode (the constant-velocity map is
linear, so the shift of the state at :math:`t_k` is the shift at
:math:`t_0` carried forward; the smoother's process-noise wiggles are
kept).  Where the process noise has a share, the estimate
:math:`\hat{\mathbf x}_0` lies away from the samples' mode by what the
process noise lets the track do at its start, which is not skew.  Until
2026-12-02 the shift was taken from :math:`\hat{\mathbf x}_0`: it carried
that distance along the whole track as a velocity offset, pulling the
track towards the constant-velocity one; and where the importance-sampled
mean passed the first check by its weights' scatter alone, it moved a
track with no skew at all (a four-pair recording at 20 Hz for 120 s whose
moved samples' mean lay 0.0015 from their mode: 8 m at the end, five of
its own standard deviations, with the status ``ok``; hence the second
measurement).  Where the mode lies more than :data:`MODE_APART_MAX` (two
standard deviations) from the estimate, nothing is reported: the data
hold the track away from every constant-velocity one, so the samples map
another posterior than the smoother's.  Measured with truths that carry
the model's own process noise (:math:`q = 10^{-3}` m²/s³, 120 s, 40 runs
per cell; a script not kept), the shift from the estimate against the
shift from the mode with that limit: four pairs at 2 Hz, position RMSE
9.1 → 3.5 m, run-averaged NEES 62.8 → 4.35, runs ending beyond χ²₄
99.9 % 13 → 0; random layouts at 5 Hz, NEES 11.8 → 6.2, 4 → 1; cases a
and b 25 km flown for 120 s, 600.8 → 587.1 m and 797.0 → 775.1 m; the
same with the truth at exactly constant velocity, 764.4 → 757.8 m and
741.9 → 747.0 m (docs/concepts.md, "The skew alone").  The covariances take the samples' covariance about
their mean in place of :math:`\mathbf\Sigma_0` above, not enclosed (a lopsided
posterior is narrower than its Gaussian model on its steep side): where
:math:`\mathbf E` then narrows a matrix, its whitened eigenvalues against
:math:`\mathbf P^\mathrm L_k` are kept at or above the samples' own
narrowing of :math:`\mathbf C` (:func:`_carried`).  Measured (100 runs per scenario, seeds 2026 and 7,
this check's :math:`w`; ``studies/skewed_mean_check.py``): 0.080-1.005 in
every run of the 25 km scenarios, 0.003-0.012 in every run of case a 45 km
and case b 5 km, where the Laplace covariance stands; a run near the limit
loses little either way, its mean a fifth of a standard deviation from the
MAP.  The curved-valley scenarios (case a 5 km, case b 45 km) are sampled
by the probe and keep the MAP, which is 38-60 m closer to the truth there
than the sample mean would be (docs/concepts.md).  In the 25 km
scenarios the mean is 33-87 m closer (RMSE over t ≥ 5 s, paired) and its
covariance brings the run-averaged NEES to the exact posterior's (case a
25 km 4.61 → 4.18 with seed 2026, exact 4.16; case b 25 km seed 7 4.17 →
3.71, exact 3.72).

Beyond :data:`TRUST_LIMIT` the sampled covariance is still reported but the
finding is ``"doubtful"``: local Metropolis moves cannot map a likelihood
that bends that much.  Measured (8 seeds per scenario): the paper's six 2-D
scenarios give ratios of 7-11 where they sample at all, with end-of-track
NEES 0.3-10; the same scenarios flown at 1-10 km over the paper's ground
sensors (3-D, where the target's rotation about the near-collinear
baseline is barely observable) give 1e4-2e5, with NEES in the thousands.

Valleys that reach far
----------------------
The importance proposal :math:`\mathcal N(\hat{\mathbf x}_0, 4\mathbf P_0)`
reaches two Laplace standard deviations, and 20 Metropolis sweeps from it
move the samples a few of their own widths.  Where a radar's Doppler leaves
the track's rotation about it to one other pair, the valley reaches
kilometres further.  Measured with ``python studies/sampled_spread_check.py
--draws 150 --narrow 1`` (2026-11-30), against the exact posterior's second
moment about the same estimate (``benchmarks/_exact.py``, adaptive
importance sampling, no code shared): on a radar and one bistatic pair
(150 recordings) the samples' second moment put the truth beyond a NEES of
18.5 (χ²₄ at 99.9 %) in 102, in 83 of them where the exact one held it
(median NEES 193 against 5.9; the major standard deviation a median 0.56
of the exact one's); on random and radar layouts 7 of 96 sampled tracks
were such misses.  Three signs mark such a valley: the probe's ratio
beyond :data:`BEND_LIMIT`; a one-step importance draw from the narrow
proposal that leaves fewer than :data:`ESS_MIN` effective samples; or, where
neither does, a probe from the samples' own spread (:func:`_growth`: 1,024
draws tempered in from four times their standard deviations, twice) whose
second moment grows beyond :data:`GROWTH_LIMIT` times theirs, because the
valley runs on past them.  There the samples are drawn from a
broad proposal instead (:func:`_sample_reaching`): tempered into the
posterior
(:meth:`~fgdoppler.estimators.particle_posterior._Posterior.sample_from`)
from :math:`\mathcal N(\hat{\mathbf x}_0, 36\,\mathbf P_0)` and moved,
then twice more the same way, each time from four times the samples' own
standard deviations about their mean, so that each pass covers what the
last found, and up to :data:`MAX_ADAPTED_PASSES` times while their spread
still grows by :data:`PASS_GROWTH` from one pass to the next
(:func:`_sample_broad`).  With the first two signs (``--narrow 0`` before the growth
probe, 9-12 min on 2 cores): the broad proposal ran on 133 of the 150
radar-and-pair tracks and on 41 of the 96 others; the misses where the
exact posterior holds fell from 83 to 11 (median NEES 5.5, standard
deviation ratio 1.07) and from 7 to 0, 80 tracks now holding the truth
and none the other way.  But the effective sample size found a valley by
chance: radar-and-pair draw 0 took the broad proposal with sampler seeds 0
and 7 only (effective samples 29 and 2; 130-251 with seeds 1-6, whose
samples held a third of the exact standard deviation), draws 7 and 100
with 3 of 8 seeds each.  With the growth probe it runs with all 8 seeds on
each of the three (the standard deviation 0.75-1.66 of the exact one's,
which on draw 7 is itself uncertain, 5.3-8.4 km); on the study's draws
(``python studies/sampled_spread_check.py --draws 150``, 7 min, 2026-11-30,
on another machine than the figures above: there the two signs left 11
misses too) it ran on 146 of 150 radar-and-pair tracks and on 48 of the 96
others, tracks whose truth's NEES exceeds 100 fell from 16 to 9 (the exact
posterior's: 6) and those whose standard deviation is below half the
exact one's from 9 to 5; the misses where the exact posterior holds went
from 11 to 10 and from 0 to 0 (one fixed, none new).  Following a valley
that the passes are still opening up (up to five of them; the same run):
the radar-and-pair misses where the exact posterior holds fell from 10 to 4
and the tracks beyond a NEES of 18.5 from 30 to 21 (the exact posterior's:
20), those beyond 100 from 9 to 7, with 2, 3, 4 and 5 passes on 87, 31, 20
and 8 of the 146 (about 0.35 s of CPU each); on the 96 layout tracks the
misses went from 0 to 1 (radar draw 77, whose exact posterior rests on 7
effective samples: NEES 9.5 to 23.5 against 3.3) and the tracks beyond
18.5 stayed 23.  None of the three
signs fires on the paper's recordings (the accuracy benchmark's 400
sampled ones, case a 5 km and case b 45 km with seeds 2026 and 7: probe
ratio at most 11.8, effective samples at least 150, growth at most 3.3
with two seeds of the probe's own; the library's, as it runs, leaves all
400 on the narrow proposal), whose covariances are unchanged to the bit;
the probe costs 0.10 s of CPU per sampled track there (median; the
smoother 0.55 s without it and 0.67 s with it on 15 recordings each of
case a 5 km and case b 45 km, run alternately), the broad proposal
1.1-1.5 s where it runs.
In 3-D too since 2026-12-07 (late; until then the narrow proposal stayed
there, unmeasured, and the exact posterior of a 6-D state is no reliable
reference: on draws of ``studies/random_layouts_3d.py`` its importance
sampler kept 2-88 effective samples in 5 of 11).  Measured against the
narrow proposal alone, the truth's NEES of the 6-D state: the altitude
table of docs/reproduction.md (``python studies/altitude_study.py --runs
10``, 1,258 s against 1,141 s) fell in all 24 cells of the smoother's end
NEES (case a 45 km at ground level 1,620 → 21.2, case b 25 km at 10 km
1,060 → 4.8, case a 5 km at ground level 45,300 → 358), none rose, every
other column equal; the masts cell of ``studies/process_noise_share.py``
(run-averaged over t ≥ 10 s) 19.18 → 11.56, runs beyond the χ²₆ 99.9 %
point 2 → 1 (run 10: 40.1 → 3.4; run 18: 303 → 200), median smoother CPU
3.3 → 4.2 s; draws 0-15 of ``studies/random_layouts_3d.py`` flown 120 s
(the smoother alone): the broad proposal ran on 4, draw 14 went 120 → 11.8,
the other three 3.2 → 1.0, 1.0 → 0.3 and 1.4 → 2.5, every status the same
(docs/concepts.md, "The broad proposal in 3-D").

Where the process noise matters
-------------------------------
The samples move at exactly constant velocity, so they describe the
smoother's posterior only where the data, not the process noise, set its
spread.  Along the probe's axis :math:`\boldsymbol\delta`
(:func:`~fgdoppler.estimators.curvature.probe_axis`,
:math:`\boldsymbol\delta^\top\mathbf P_0^{-1}\boldsymbol\delta = 1`) the
sampled cost's own Gauss–Newton information :math:`\mathbf I_\mathrm{cv}`
(:func:`_information`) says how much of the smoother's variance the
constant-velocity track accounts for, :math:`1/\boldsymbol\delta^\top\mathbf I_\mathrm{cv}\boldsymbol\delta`;
below :data:`DETERMINISTIC_MIN` nothing is sampled and the Laplace
covariance stands.  On the paper's data (σ = 1 m/s, 30 s) the share is
0.997-1.013 in all 1,200 recordings of the accuracy benchmark.  With precise Doppler the data fix a 30 s track to
metres, as closely as the process noise does (:math:`q = 10^{-3}` m²/s³: 3 m
and 0.17 m/s of standard deviation after 30 s): on case a 45 km with
σ = 0.05 m/s the share was 0.09, the probe, measuring the constant-velocity
cost against :math:`\mathbf P_0`, found it 11 times off, and the samples,
carried with :math:`\mathbf Q(t_k - t_0)` as they then were, made the last covariance up to
195 times the EKF's in variance.  Long recordings reach the same point more
slowly (case a 5 km and case b 45 km: 120 s).

Below the limit nothing is sampled; the smoother's own cost is probed along
the whole track and profiled along its valley where the probe strays beyond
:data:`SAMPLING_LIMIT`, as beyond :data:`MAX_SPAN`
(:mod:`~fgdoppler.estimators.trajectory_bend`, :func:`_unsampled_bend`):
the track is reported unchanged, its covariances enclosing the profiles'
second moments, with the profile's ``nonlinear`` finding (informational
in 2-D where every profile is trusted, ``doubtful`` in 3-D or where one is
not; in 3-D, where that finding is always ``doubtful``, the profile is
taken only where the constant-velocity probe below finds a bend).  The constant-velocity probe still runs (five costs), against the
sampled cost's own quadratic model as above: that cost is the data's
likelihood of a straight track, and where it rises beyond the verdict's
:data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT` times its quadratic
model the message says so, beyond :data:`TRUST_LIMIT` the finding is
``doubtful``, and where the whole-track probe finds no valley the Laplace
covariance is reported with a ``doubtful`` finding.  Where that cost falls
off the estimate (a negative ratio: the process noise moved the smoother's
track off the straight track's minimum) it says nothing about the
smoother's posterior.  Measured (``python studies/process_noise_share.py``,
its 3-D cell: four pairs on masts, an aircraft 50-70 km out, 60 s, 20
runs): eight runs had shares 0.045-0.24 and ratios 56-3.0·10⁴, every one
``ok`` before 2026-12-06 with a run-averaged NEES of 8-435 for six
dimensions (the position block alone 0.29-1.72 in all of them: the truth
lies off a thin direction mixing speed and position), 0.9-12.2 with the
profiles, ``doubtful``; the 2-D cells above (shares 0.09-0.11) give
ratios 0.89-1.0 and stay as they were.  A random 3-D layout over 60 s with
share 0.23 and ratio 271 became ``doubtful`` at a NEES of 4.3, as the same
ratio above the limit already made it: the finding is the probe's, not the
NEES's.  On 2-D recordings of 150-300 s (``python
studies/unsampled_profiles.py``; docs/concepts.md, "Where nothing is
sampled") the profiles took the run-averaged NEES of sixteen 300 s
recordings of case a from 5.10 to 4.38 (final NEES beyond the χ²₄ 99.9 %
point 1 → 0), and the four ``doubtful`` findings there, all from negative
constant-velocity ratios, became informational.

Above the limit the process noise still has its share, so both tests that
decide on sampling compare the sampled cost with itself, not with the
smoother: the probe's quadratic model is that cost's own,
:math:`9\,\boldsymbol\delta^\top\mathbf I_\mathrm{cv}\boldsymbol\delta`
(against :math:`\mathbf P_0^{-1}`, whose freedom along the axis the
constant-velocity track does not have, a quadratic cost looks
:math:`1/\text{share}` times steeper), and the skewness check measures the
samples' mean from the sampled posterior's own mode (:meth:`~fgdoppler.estimators.particle_posterior._Posterior.mode`,
Levenberg–Marquardt from the estimate), from which the smoother's estimate
differs by what the process noise lets the track do.  With σ = 0.1 and
0.2 m/s (case a 45 km, shares 0.32 and 0.81) comparing with the smoother
sampled 20 of 20 runs (the probe: more than 3 times off) and reported a
"skewed" mean in 14 of 20 (0.2-0.3 standard deviations from the estimate),
and the carried samples made the EKF's verdict ``doubtful`` in 20 and 14 of
20 consistent runs; compared with itself the cost is quadratic and
unskewed there and the Laplace covariance stands.  On the paper's data,
where the share is within 1.3 % of one, the two comparisons give the same
tracks, covariances and verdicts to the bit (1,200 recordings).
docs/concepts.md, "Precise Doppler", has the measurements.

Filtered covariances
--------------------
:func:`filtered_spread` does the same for a filter's estimates, which must
not read data after their own time.  At a check at time :math:`t_c` the
filtered estimate is carried back to the first measurement's time
:math:`t_0` under the deterministic motion,
:math:`\hat{\mathbf x}_0 = \mathbf F(t_0 - t_c)\hat{\mathbf x}_c`,
:math:`\mathbf P_0 = \mathbf F(t_0 - t_c)\mathbf P_c\mathbf F(t_0 - t_c)^\top`;
:data:`FILTER_SAMPLES` samples of the posterior of :math:`\mathbf x_0`
given the measurements up to :math:`t_c` (the model's prior and zone) are
drawn about it (importance sampling from
:math:`\mathcal N(\hat{\mathbf x}_0, 4\mathbf P_0)`, resampling,
:data:`FILTER_MOVES` Metropolis sweeps), and their second moment about
:math:`\hat{\mathbf x}_0`, carried forward,
:math:`\mathbf S_c = \mathbf F(t_c - t_0)\mathbf\Sigma_0\mathbf F(t_c - t_0)^\top + \mathbf Q(t_c - t_0)`,
is the posterior mean-square error of the filter's estimate.  The filter's
covariances from that check on grow in every whitened direction where
:math:`\mathbf S_c` exceeds :math:`\mathbf P_c` more than
:data:`FILTER_WIDEN_MIN` times, and never shrink.  The threshold lies above
the sampler's own noise: in the paper's case a 45 km (iSAM2, 40 runs, 440
checks, seed 2026), whose filtered NEES is consistent, the largest
whitened ratio of a check has median 1.19 and 99th percentile 2.28.

Unlike the smoother's, every check samples: the curvature probe sees 3
standard deviations, and on a poorly observed track the posterior reaches
further than that where the cost is still quadratic at 3 (case a 5 km,
seed 2026, run 79: at 25 s iSAM2's Gaussian covariance gives a position σ
of 268 m and the probe a ratio of 1.06, posterior samples about 600 m; the
estimate is 2.7 km off).  Checks fall ``interval`` seconds apart; after a
check that widened nothing the interval doubles (up to
:math:`2^{3}` times, :data:`FILTER_BACKOFF`), and it is never less than a
tenth of the time since :math:`t_0`, so a long recording costs a bounded
number of likelihood evaluations per measurement.  A check samples only
while the process noise accumulated since :math:`t_0`, whitened by the
filter's covariance, stays below :data:`FILTER_NOISE_MAX` in every
direction (and none is made beyond :data:`MAX_SPAN`): beyond, the samples'
deterministic motion no longer describes the filter's posterior.  Without
that guard, on a slow three-pair track of 600 s whose iSAM2 NEES is 3.52,
the :math:`\mathbf Q(t_c - t_0)` term alone widened 26 of 27 checks and
brought it to 2.73 (+30 % time); with it, 3 of 12 checks widen, NEES 3.52,
+0.1 s.  On the paper's 30 s scenarios it changes 2 of the 1,200 runs of
the accuracy benchmark, neither run-averaged NEES.

Beyond the samples' reach the filter's covariance is not simply left as it
is: over minutes of a poorly observed track a filter linearised at its own
predictions claims more than the data allow.  Given the offline smoother's
track (``reference``; :func:`~fgdoppler.estimators.registry.run_estimator`
passes the verdict's), every filtered covariance from a check beyond reach
up to the next check within it (and all beyond :data:`MAX_SPAN`) is widened
the same way, at its own time, towards the posterior mean-square error of
its estimate under the posterior of the data so far linearised about that
track (:mod:`~fgdoppler.estimators.linearized_posterior`: a Kalman filter
that reads the same measurements but linearises them where the whole
recording puts the target).  Measured on 600 s recordings of the paper's
pairs with the model's own process noise (``studies/long_filters.py``, 12
per case): the EKF's run-averaged NEES 9.2 and 9.0 → 4.3 and 3.8, iSAM2's
6.0 and 6.5 → 4.4 and 4.1, the offline smoother's 4.7 and 3.1; the runs
beyond the χ²₄ 99.9 % point 3 → 0.  Lagged estimates (``lag > 0``) are
widened the same way towards the posterior of the data up to one lag
after their time (the linearised filter smoothed back from there): the
fixed-lag smoother's NEES on the same recordings 7.4 and 729 → 4.7 and
35, its runs beyond the point 3 → 1, that one judged ``doubtful`` (with
``linearised_everywhere``, below: 4.7 and 4.4, none beyond the point).

With ``linearised_everywhere`` (``SampledCovarianceSettings.linearised_everywhere``,
the registry's default) that linearised
enclosure applies at every estimate, after the sampled checks: a check's
widening is carried to the next check, and a covariance that changes shape
between two checks (or after the checks have backed off) can understate
the error there.  On the accuracy benchmark's 30 s recordings (100 runs per
scenario) it took iSAM2 in case a 25 km, seed 2026, run 75 from a
run-averaged NEES of 20.6, judged ``ok``, to 7.3, and the inconsistent
runs judged ``ok`` of the three estimators it applies to from 10 to 6
(seed 2026) and 6 to 1 (seed 7); in case b 45 km (seed 2026) and case a
5 km (seed 7) the NEES falls below the 95 % band (2.87–3.36): an enclosure
of two covariances is wider than either.  Widened towards the reference's
own track, the covariances can no longer disagree with it: the verdict's
whole-track ``reference`` finding reads :attr:`FilteredSpread.checked`,
the covariances without that enclosure (where the reference is wrong, an
unmodelled manoeuvre, the disagreement is the evidence).

Lagged estimates
----------------
The fixed-lag smoother's estimate of the state at :math:`t` has read the
data up to about :math:`t + \ell` (its lag): ``filtered_spread(...,
lag=ℓ)`` samples, at a check at :math:`t_c`, the posterior given the
measurements up to :math:`t_c + \ell` instead, everything else as above.
A check that ignored the look-ahead would credit the estimate with less
data than it saw: measured on the fixed-lag smoother's 600 runs of the
accuracy benchmark (seed 2026), the lag-blind check brought the
run-averaged NEES of case b 45 km from 3.77 to 2.12, the lag-aware one to
2.97, and case a 5 km from 6.04 to 3.80 and 4.62 (docs/concepts.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fgdoppler.estimators.curvature import CURVATURE_LIMIT, probe_axis, probe_rises
from fgdoppler.estimators.linearized_posterior import linearized_filter, mean_square_errors
from fgdoppler.estimators.particle_posterior import _Data, _Posterior, _weighted_cov
from fgdoppler.estimators.settings import ParticleSettings
from fgdoppler.estimators.trajectory_bend import TrackBend, track_bend
from fgdoppler.estimators.verdict import Reason, Status
from fgdoppler.measurements import Measurements
from fgdoppler.models.robust import huber_weights
from fgdoppler.models.tracking import TrackingModel

__all__ = ["ADAPTED", "ADAPTED_PASSES", "BEND_LIMIT", "BROAD", "ESS_MIN", "FILTER_MOVES", "FILTER_SAMPLES",
           "GROWTH_LIMIT", "MAX_ADAPTED_PASSES", "MAX_SPAN", "MEAN_SHIFT_MIN", "MODE_APART_MAX", "PASS_GROWTH",
           "PROBE_MOVES", "PROBE_PASSES", "PROBE_SAMPLES", "SAMPLES", "SAMPLING_LIMIT", "TRUST_LIMIT",
           "FilteredSpread", "PosteriorSpread", "filtered_spread", "posterior_spread"]

FloatArray = NDArray[np.float64]

#: Posterior samples drawn (their Monte Carlo error on a variance is about √(2/ESS), a few per cent).
SAMPLES = 4096
#: Ratio of the probe's cost rise to its quadratic model beyond which (or below whose inverse) the covariance
#: is sampled.
SAMPLING_LIMIT = 3.0
#: Probe ratio beyond which the sampled covariance is not trusted either (module docstring): the finding is
#: ``"doubtful"``.  Ten times the largest ratio measured in the paper's 2-D scenarios.
TRUST_LIMIT = 100.0
#: Probe ratio beyond which (or below whose inverse) the valley bends out of the reach of the importance
#: proposal :math:`\mathcal N(\hat{\mathbf x}_0, 4\mathbf P_0)` and of local moves from it: the samples are drawn
#: from a broad proposal instead (:func:`_sample_reaching`; module docstring, "Valleys that reach far").  Measured
#: 2026-11-30: at most 11.8 on the accuracy benchmark's 400 sampled recordings (case a 5 km and case b 45 km, 100
#: runs each with seeds 2026 and 7; the default smoother on each, a script not kept); 18-2,500 on random and radar
#: layouts where the samples fell short of the exact posterior's spread (``studies/sampled_spread_check.py``).
BEND_LIMIT = 15.0
#: Effective sample size of the one-step importance draw from :math:`\mathcal N(\hat{\mathbf x}_0, 4\mathbf P_0)`
#: below which its moments rest on too few draws and the broad proposal is used too.  Measured 2026-11-30 (a
#: script recording ``proposal_ess`` in the smoother's runs, not kept): at least 150 (1 % quantile 177) on the
#: benchmark's 400 sampled recordings; 4-74 in 16 of 22 tracks (150 draws each of the study's random and radar
#: layouts, 20 of the radar and pair) whose samples fell short of the exact posterior's spread.
ESS_MIN = 100.0
#: Growth of the samples' spread beyond which the valley reaches past the narrow proposal and the broad one is
#: used too (:func:`_growth`): a probe of :data:`PROBE_SAMPLES`, tempered into the posterior from four times the
#: narrow samples' own standard deviations about their mean and then :data:`PROBE_PASSES` - 1 times more from its
#: own, against the narrow samples in the largest eigenvalue of the second moment about the estimate in the
#: Laplace metric.  Where the posterior ends within the narrow proposal's reach each pass finds what the last one
#: found; where a valley runs on the passes compound.  The effective sample size alone misses such valleys by
#: chance: on the radar-and-pair draw 0 of ``studies/sampled_spread_check.py`` it was 2 and 29 with sampler
#: seeds 7 and 0 and 130-251 with seeds 1-6, whose samples then held 0.32-0.35 of the exact posterior's standard
#: deviation.  Measured 2026-11-30 with two probe seeds (a script not kept): on the accuracy benchmark's 400
#: sampled recordings the growth was a median 1.34-1.36 and at most 3.33 (one recording; the next 2.51); on the
#: 15 radar-and-pair draws (of 150) whose curved-valley samples put the truth beyond a NEES of 18.5 with neither
#: other sign, above the limit in 10 and 8 of 15 (in 6 and 5 of the 6 where the exact posterior held the truth).
GROWTH_LIMIT = 4.0
#: Samples and passes of the growth probe, and the Metropolis sweeps of each pass (it measures a second moment,
#: not a covariance to report: 0.10 s of CPU, module docstring).
PROBE_SAMPLES, PROBE_PASSES, PROBE_MOVES = 1024, 2, 5
#: The broad proposal's covariance in units of :math:`4\mathbf P_0`: standard deviations six times the Laplace
#: covariance's.
BROAD = 9.0
#: The broad proposal's later passes: each one's covariance in units of four times the previous pass's samples'
#: covariance (standard deviations four times theirs, about their mean).
ADAPTED = 4.0
#: Fewest passes from the previous pass's samples after the first broad one: each covers what the last found.
#: Measured on the first 40 radar-and-pair draws of ``studies/sampled_spread_check.py``: misses where the exact
#: posterior holds 6 with one such pass, 3 with two (median NEES 6.5 and 4.7); each costs about 0.35 s of CPU.
ADAPTED_PASSES = 2
#: Most such passes, and the growth of the samples' second moment (its largest eigenvalue in the Laplace metric)
#: from one pass to the next beyond which another follows: a valley that the passes are still opening up is
#: followed further (module docstring, "Valleys that reach far").
MAX_ADAPTED_PASSES, PASS_GROWTH = 5, 1.5
#: Longest recording (s) sampled: beyond it the deterministic constant-velocity approximation fails (with
#: q = 1e-3 m²/s³ the process noise moves a 300 s track by 95 m, a 2-hour one by 11 km) and the cost grows
#: with every measurement; the Laplace covariance stands there.
MAX_SPAN = 300.0
#: Smallest share of the smoother's variance along the probe's axis that the sampled cost, whose track moves at
#: exactly constant velocity, must account for (:func:`_information`); below it the process noise sets that
#: variance and the Laplace covariance stands (module docstring, "Where the process noise matters").  Measured
#: shares fall in two groups: 0.09-0.11 where the process noise sets the spread (precise Doppler; 120 s of
#: case a 5 km or case b 45 km) and 0.45-1.03 elsewhere (0.997-1.013 on the paper's recordings, 0.45-1.0 on
#: 120 s of the 25 km scenarios, where a limit of 0.5 cost 8 and 17 m of RMSE over 20 runs); the limit lies between
#: (``studies/process_noise_share.py``).
DETERMINISTIC_MIN = 0.25
#: What a ``"doubtful"`` ``nonlinear`` finding beyond :data:`TRUST_LIMIT` says.
_BEYOND_TRUST = f"beyond {TRUST_LIMIT:g} times no Gaussian covariance describes the posterior"
_FAR_OFF = ": the estimate and its covariance may be far off (the data barely determine the state)"
#: Metropolis sweeps after resampling (enough for the samples to spread along a curved valley).
MOVES = 20
#: Squared Mahalanobis length (in the Laplace covariance) of the sampled posterior's mode's distance from the
#: smoother's first estimate beyond which no posterior mean is reported: the process noise holds the track that far
#: from every constant-velocity one, so the samples' posterior (and its skew) is not the smoother's.  Two standard
#: deviations.  Measured (module docstring, "Skewed valleys"): at most 0.017 on the paper's 25 km recordings (the
#: accuracy benchmark's 400, seeds 2026 and 7), at most 1.64 on the 25 km scenarios flown for 120 s (the 112 of
#: 160 runs that reported the mean; truths with and without process noise), 13-77 in the 17 runs that did of four
#: pairs at 2 Hz and random layouts at 5 Hz (120 s, truths with the model's own process noise), whose mean ended
#: with a NEES of 10-4,300.
MODE_APART_MAX = 4.0
#: Squared Mahalanobis length (in the Laplace covariance) of the importance-sampled posterior mean's shift from
#: the sampled posterior's mode beyond which, where the probe finds the cost near-quadratic, the posterior mean is
#: reported.  Measured: 0.080-1.005 in the paper's 25 km scenarios, at most 0.012 in the well-observed ones
#: (module docstring); the threshold sits between, a fifth of a standard deviation.
MEAN_SHIFT_MIN = 0.05
#: Posterior samples per check of a filter's covariance (:func:`filtered_spread`): a check every few seconds
#: must cost a fraction of the filter.
FILTER_SAMPLES = 1024
#: Metropolis sweeps per check of a filter's covariance.
FILTER_MOVES = 10
#: Whitened variance ratio (samples / filter) a direction must exceed to be widened at a check.
FILTER_WIDEN_MIN = 2.0
#: After this many checks in a row that widened nothing the interval stops doubling (at 2**FILTER_BACKOFF times).
FILTER_BACKOFF = 3
#: A check samples only while the process noise accumulated since the first measurement, whitened by the
#: filter's covariance, stays below this in every direction: beyond, the samples' deterministic motion no
#: longer describes the filter's posterior (on a slow 600 s track it widened consistent covariances, NEES 3.52
#: -> 2.73, by the noise term alone).
FILTER_NOISE_MAX = 1.0


@dataclass(frozen=True, kw_only=True)
class FilteredSpread:
    """What :func:`filtered_spread` widened.

    Parameters
    ----------
    covariances
        ``(n, 2d, 2d)``: the covariances widened by the sampled checks and
        the linearised enclosure.
    checked
        The covariances widened by the sampled checks alone, where the
        linearised enclosure widened any (else ``None``: ``covariances``).
        The enclosure is built from the reference track; a finding that
        compares the estimates with that track reads these.
    reason
        The informational ``nonlinear`` finding: what was widened, by how
        much, and where most.
    """

    covariances: FloatArray
    checked: FloatArray | None
    reason: Reason


@dataclass(frozen=True, kw_only=True)
class PosteriorSpread:
    """What the smoother reports where its Laplace approximation misdescribes the posterior.

    Attributes
    ----------
    states
        ``(n, d)`` estimates: the input ones where the probe found a curved
        valley, the posterior mean's track where it found a skewed one.
    covariances
        ``(n, d, d)`` the posterior mean-square error about ``states``; the
        input (Laplace) ones where the process noise forbids sampling and
        the finding says that they are not to be trusted.
    reason
        An informational ``nonlinear`` finding that says what was done
        (``"doubtful"`` beyond :data:`TRUST_LIMIT`, and always with the
        untrusted Laplace covariances).
    """

    states: FloatArray
    covariances: FloatArray
    reason: Reason


def posterior_spread(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
                     covariances: FloatArray, *, huber_k: float | None = None, seed: int = 0,
                     mean: bool = True) -> PosteriorSpread | None:
    """Sampled covariances (and, in a skewed valley, the posterior mean) where the Laplace approximation fails.

    Parameters
    ----------
    measurements
        The recording.
    model
        Observation, motion, prior and zone (the zone is the support of the first state).
    times, states, covariances
        The smoother's times ``(n,)``, estimates ``(n, d)`` and Laplace covariances ``(n, d, d)``.
    huber_k
        Huber threshold of the likelihood (``None``: Gaussian).
    seed
        Seed of the sampler (the same input gives the same result).
    mean
        Where the probe finds the cost near-quadratic, check whether the
        posterior mean lies more than :data:`MEAN_SHIFT_MIN` (squared
        Mahalanobis length) from the sampled posterior's mode and if so
        report it (module docstring, "Skewed valleys").  ``False``: the estimate always stands.

    Returns
    -------
    PosteriorSpread or None
        ``None`` when the Laplace approximation stands: the probe finds it
        fair and the posterior mean is not shifted (or ``mean`` is off),
        the recording is longer than :data:`MAX_SPAN` and the probe of the
        whole track finds its likelihood within :data:`SAMPLING_LIMIT` of
        the Laplace model (beyond it the input track comes back with the
        covariances widened to enclose its profiles' second moments:
        :func:`~fgdoppler.estimators.trajectory_bend.track_bend`), the process noise
        sets the variance along the probe's axis (:data:`DETERMINISTIC_MIN`)
        and neither the probe of the whole track strays beyond
        :data:`SAMPLING_LIMIT` (beyond it the input track comes back with
        the covariances enclosing its profiles) nor the constant-velocity
        probe beyond :data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT`
        (beyond it the input track and covariances come back unchanged,
        with a ``"doubtful"`` finding), or the sampler cannot run (no
        finite posterior around the estimate).
    """
    t0 = float(times[0])
    if float(times[-1]) - t0 > MAX_SPAN:  # nothing is sampled: the cost is profiled where the probe finds it bent
        return _profiled(measurements, model, times, states, covariances, huber_k)
    x0, P0 = np.asarray(states[0], dtype=float), np.asarray(covariances[0], dtype=float)
    try:
        info = np.linalg.inv(P0)
        np.linalg.cholesky(covariances)  # the samples' excess is carried on them
    except np.linalg.LinAlgError:
        return None
    post, data = _posterior(measurements, model, t0, huber_k, seed, SAMPLES)

    def cost(x: FloatArray) -> float:
        return float(-2.0 * post.loglik(x[None], data.t, data.pair, data.z, data.sigma)[0])

    axis = probe_axis(P0)[0]  # one standard deviation: axis' P0^-1 axis = 1
    icv = _information(model, data, x0, huber_k, info)
    share = 1.0 / float(axis @ icv @ axis)
    # the sampled cost against its own quadratic model: P0 also holds the process noise's freedom, which that
    # cost does not, and would make a near-quadratic cost look curved wherever the process noise has a share
    lo, hi, quad, _ = probe_rises(cost, x0, P0, icv)
    ratio = min(lo, hi) / quad
    if share < DETERMINISTIC_MIN:
        # the process noise, not the data, sets the uncertainty the samples would map: none are drawn, but a
        # bend the Laplace covariance cannot describe must still be said
        return _unsampled_bend(measurements, model, times, states, covariances, ratio, share, huber_k)
    rng = np.random.default_rng(seed)
    laplace, own = np.asarray(covariances, dtype=float), _own_model(icv, P0)
    if 1.0 / SAMPLING_LIMIT <= ratio <= SAMPLING_LIMIT:
        return _skewed(post, model, times, states, laplace, own, info, ratio, rng) if mean else None
    return _curved(post, model, times, states, laplace, own, ratio, rng, measurements=measurements, huber_k=huber_k)


def _profiled(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
              covariances: FloatArray, huber_k: float | None) -> PosteriorSpread | None:
    """Beyond :data:`MAX_SPAN`: the Laplace covariances enclosing the second moments of the profiles of
    :func:`~fgdoppler.estimators.trajectory_bend.track_bend` (taken where its probe strays beyond
    :data:`SAMPLING_LIMIT`), with its finding; ``None`` where it takes none."""
    bend = track_bend(measurements, model, times, states, covariances, limit=SAMPLING_LIMIT, huber_k=huber_k)
    if bend is None:
        return None
    return PosteriorSpread(states=np.asarray(states, dtype=float), covariances=_enclosing_profiles(covariances, bend),
                           reason=bend.reason)


def _enclosing_profiles(covariances: FloatArray, bend: TrackBend) -> FloatArray:
    """``covariances`` widened in every whitened direction to enclose each profile's finite second moments."""
    widened = np.asarray(covariances, dtype=float)
    for profile in bend.profiles:
        if np.all(np.isfinite(profile.moments)):
            widened = _widened_stack(widened, profile.moments, 1.0)[0]
    return widened


def _curved(post: _Posterior, model: TrackingModel, times: FloatArray, states: FloatArray, laplace: FloatArray,
            own: FloatArray, ratio: float, rng: np.random.Generator, *, measurements: Measurements,
            huber_k: float | None) -> PosteriorSpread | None:
    """The sampled covariances and their ``nonlinear`` finding where the probe's ``ratio`` is beyond
    :data:`SAMPLING_LIMIT`; ``None`` where no sample reaches the posterior.  ``laplace``: the smoother's
    covariances; ``own``: the sampled cost's Gaussian model of the first state (:func:`_own_model`);
    ``measurements`` and ``huber_k``: the recording and the Huber threshold (for the profile beyond trust).

    Beyond :data:`TRUST_LIMIT` the covariances are widened further to the second moments of the smoother's own
    cost profiled along the valley (:func:`~fgdoppler.estimators.trajectory_bend.track_bend`): measured on
    the 3-D cell of ``studies/process_noise_share.py`` (four pairs on masts, 60 s, 20 runs), the twelve sampled
    runs beyond it had a run-averaged NEES of 2.0-569 with the samples alone, 7 of them beyond the χ²₆ 99.9 %
    point (22.5), and 0.9-367 with both, 4 beyond it (docs/concepts.md, "The valley followed"); with the 3-D
    profile held on two axes too (2026-12-07, evening) 0.6-303, 2 beyond it ("Two axes in 3-D"); with the broad
    proposal in 3-D too (2026-12-07, late) 0.3-200, 1 beyond it."""
    x0, P0 = np.asarray(states[0], dtype=float), laplace[0]
    drawn = _sample_reaching(post, x0, P0, ratio, rng)
    if drawn is None:
        return None
    sampled, rate, broad = drawn
    carried = _carried(model, laplace, _enclosing(own, sampled) - own, times, 1.0)
    spread = _weighted_cov(post.x, np.full(SAMPLES, 1.0 / SAMPLES))
    trusted = 1.0 / TRUST_LIMIT <= ratio <= TRUST_LIMIT
    warning = "" if trusted else f"; {_BEYOND_TRUST} and local samples cannot map it{_FAR_OFF}"
    if not trusted:
        bend = track_bend(measurements, model, times, states, laplace, limit=SAMPLING_LIMIT, huber_k=huber_k)
        if bend is not None:
            carried = _enclosing_profiles(carried, bend)
            warning += f"; widened further to the second moments of the smoother's own cost, {bend.widening}"
            if bend.untrusted:
                warning += f", which is not to be trusted either ({bend.untrusted})"
    pos = slice(0, model.dim)
    sd_laplace, sd_sampled, sd_reported = (_major_sd(M, pos) for M in (P0, sampled, carried[0]))
    bias = float(np.linalg.norm(post.x[:, pos].mean(axis=0) - x0[pos]))
    reason = Reason(code="nonlinear", status="ok" if trusted else "doubtful", message=(
        f"the likelihood is not Gaussian about the estimate ({_probe_text(ratio, 'the cost')}): covariances from "
        f"{SAMPLES} posterior samples "
        f"({broad}Metropolis acceptance {rate:.2f}); position sigma along the major axis {sd_reported:.0f} m (Laplace "
        f"{sd_laplace:.0f} m, samples {sd_sampled:.0f} m), posterior mean {bias:.0f} m from the estimate, spread "
        f"{_major_sd(spread, pos):.0f} m{warning}"))
    return PosteriorSpread(states=np.asarray(states, dtype=float), covariances=carried, reason=reason)


def _unsampled_bend(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
                    covariances: FloatArray, ratio: float, share: float, huber_k: float | None
                    ) -> PosteriorSpread | None:
    r"""Where the process noise's share of the variance forbids sampling: the covariances widened to the valley's
    profile where the probe of the whole track finds one (:func:`~fgdoppler.estimators.trajectory_bend.track_bend`
    at :data:`SAMPLING_LIMIT`, as beyond :data:`MAX_SPAN`; in 3-D only where the constant-velocity probe's
    ``ratio`` lies beyond :data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT`), with its finding; a
    ``"doubtful"`` ``nonlinear`` finding on the Laplace covariances where it finds none but that ``ratio`` lies
    beyond :data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT` (either way); ``None`` otherwise.

    Below :data:`DETERMINISTIC_MIN` the samples, moving at exactly constant velocity, would map another
    posterior than the smoother's, so none are drawn (module docstring, "Where the process noise matters").
    The smoother's own cost is profiled instead, and its finding is the profile's: informational in 2-D where
    every profile is trusted, ``"doubtful"`` otherwise and in 3-D.  The constant-velocity cost is the data's own
    likelihood of a straight track: where it bends
    :data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT` times beyond its quadratic model, the message says so
    too, and beyond :data:`TRUST_LIMIT` the finding is ``"doubtful"`` whatever the profile (no such 2-D
    recording has been measured).  In 3-D the profile is taken only where that probe finds its cost bent
    beyond :data:`~fgdoppler.estimators.curvature.CURVATURE_LIMIT` (either way), as before: there the
    profile's finding is always ``"doubtful"``, and on 16 random 3-D layouts flown for 120 s (draws 0-15 of
    ``studies/random_layouts_3d.py --duration 120``, the smoother alone) profiling where the probe had found
    nothing turned two consistent ``ok`` answers (run-averaged NEES of the 6-D state 7.4 and 4.3) into
    ``doubtful`` ones.

    Until 2026-12-07 (later) the profile was taken only beyond that limit and the finding was ``"doubtful"``
    whatever it found.  Measured with ``python studies/unsampled_profiles.py`` (case a from (25, 3) km at
    (20, −60) m/s, q = 0.05, seeds 1–16, and case b from (25, 2) km at (50, −50) m/s, q = 0.01, seeds 1–8, for
    150, 225 and 300 s; docs/concepts.md, "Where nothing is sampled"): on the sixteen 300 s recordings of case a
    (shares 0.007-0.07) the run-averaged NEES went from 5.10 to 4.38, final NEES beyond the χ²₄ 99.9 % point
    from 1 to 0 (42.2 → 14.1), and the four ``"doubtful"`` findings, whose constant-velocity ratios were all
    negative (−2.4 to −0.6), became informational.  On the 3-D cell of ``studies/process_noise_share.py`` (four
    pairs on masts, 60 s, 20 runs) the eight unsampled runs (shares 0.045-0.24, ratios 56-3.0·10⁴) had a
    run-averaged NEES of 8-435 for six dimensions with the Laplace covariances and 0.9-12.2 widened, all
    ``"doubtful"`` (0.2-4.7 since the 3-D profile holds two axes too, 2026-12-07 evening).
    """
    bent = not 1.0 / CURVATURE_LIMIT <= ratio <= CURVATURE_LIMIT
    if model.dim == 3 and not bent:
        # in 3-D the profile's finding is always doubtful: on 16 random layouts flown for 120 s it turned two
        # consistent answers (6-D NEES 7.4 and 4.3) into doubtful ones where this probe had found nothing
        return None
    why = (f"the process noise sets most of the variance along the major axis (the constant-velocity track "
           f"accounts for {share:.2f} of it), so")
    trusted = 1.0 / TRUST_LIMIT <= ratio <= TRUST_LIMIT
    straight = _probe_text(ratio, "the cost of a constant-velocity track")
    if ratio > 0.0 and not trusted:
        straight += f"; {_BEYOND_TRUST}{_FAR_OFF}"
    bend = track_bend(measurements, model, times, states, covariances, limit=SAMPLING_LIMIT, huber_k=huber_k,
                      unsampled=why)
    if bend is not None:
        # the profile describes the smoother's own cost; a straight track's cost falling off the estimate says
        # nothing against it, and one rising beyond TRUST_LIMIT has not been measured in 2-D
        steep = bent and ratio > 0.0
        status: Status = "doubtful" if steep and not trusted else bend.reason.status
        message = f"{bend.reason.message}; {straight}" if steep else bend.reason.message
        return PosteriorSpread(states=np.asarray(states, dtype=float),
                               covariances=_enclosing_profiles(covariances, bend),
                               reason=Reason(code="nonlinear", status=status, message=message))
    if not bent:
        return None
    reason = Reason(code="nonlinear", status="doubtful", message=(
        f"the likelihood is not Gaussian about the estimate: {straight}; {why} no posterior samples can map it, "
        "and the probe of the whole track finds no valley to follow: the Laplace covariance is reported, and it "
        "misstates the uncertainty (poor observability)"))
    return PosteriorSpread(states=np.asarray(states, dtype=float), covariances=np.asarray(covariances, dtype=float),
                           reason=reason)


def _probe_text(ratio: float, cost: str) -> str:
    """What 3 standard deviations along the major axis do to ``cost`` against its quadratic model (the probe's
    ``ratio``), in words: a rise so many times the model's, or, where the ratio is not positive, a fall below the
    estimate's cost (the estimate is not that cost's minimum)."""
    if ratio > 0.0:
        return f"3 standard deviations along the major axis raise {cost} {ratio:.3g} times its quadratic model"
    return (f"3 standard deviations along the major axis lower {cost} below the estimate's (ratio {ratio:.3g} to "
            "its quadratic model's rise)")


def _skewed(post: _Posterior, model: TrackingModel, times: FloatArray, states: FloatArray, laplace: FloatArray,
            own: FloatArray, info: FloatArray, ratio: float, rng: np.random.Generator) -> PosteriorSpread | None:
    """The posterior mean's track and covariance where the mean lies beyond :data:`MEAN_SHIFT_MIN` of the mode.

    The mode is the sampled posterior's own (:meth:`~fgdoppler.estimators.particle_posterior._Posterior.mode`, from
    the first estimate ``x0``); the reported track is the estimate moved by the mean's shift from that mode.
    Importance sampling alone (no moves) decides whether to look further, so a track whose posterior is
    Gaussian costs one evaluation of :data:`SAMPLES` likelihoods; the moved samples' mean must then still lie
    beyond :data:`MEAN_SHIFT_MIN` of the mode.  Nothing is reported where the mode lies beyond
    :data:`MODE_APART_MAX` of ``x0``: the samples then describe another posterior than the smoother's.  ``laplace``: the smoother's Laplace
    covariances; ``own``: the sampled cost's own Gaussian model of the first state, whose difference from the
    samples' covariance about their mean is added to them (:func:`_carried`, floored at the samples' narrowing
    of ``own``).
    """
    x0, P0 = np.asarray(states[0], dtype=float), laplace[0]
    if post.sample_from([(x0, P0)], SAMPLES, 0, rng, tempered=False) is None:
        return None
    # skewness is the mean's distance from the sampled posterior's own mode; the smoother's estimate differs
    # from that mode by what the process noise lets the track do, which is not skewness
    mode = post.mode(x0)

    def squared(v: FloatArray) -> float:  # squared Mahalanobis length in the Laplace covariance
        return float(v @ info @ v)

    if squared(mode - x0) > MODE_APART_MAX:
        # the data hold the track away from every constant-velocity one: the samples' posterior is not the
        # smoother's, nor is its skew
        return None
    if squared(post.x.mean(axis=0) - mode) <= MEAN_SHIFT_MIN:
        return None
    rate = post.move(MOVES, rng)
    # the skew alone moves the track: a shift from x0 would also carry x0's own distance from the mode, the
    # process noise's share, along the whole track as a velocity offset
    d = post.x.mean(axis=0) - mode
    w = squared(d)
    if w <= MEAN_SHIFT_MIN:
        # the importance weights' scatter made the first mean look shifted and the moved samples' is not
        return None
    spread = _weighted_cov(post.x, np.full(post.x.shape[0], 1.0 / post.x.shape[0]))
    carried = _carried(model, laplace, spread - own, times, min(1.0, float(_whitened_eigenvalues(own, spread)[0])))
    t0 = float(times[0])
    shifted = np.asarray(states, dtype=float) + model.motion.propagate(d, np.asarray(times, dtype=float) - t0)
    pos = slice(0, model.dim)
    reason = Reason(code="nonlinear", status="ok", message=(
        f"the posterior is skewed about the most likely track (the cost is near-quadratic 3 standard deviations "
        f"along the major axis, {ratio:.3g} times its quadratic model, but the posterior mean lies {np.sqrt(w):.2f} "
        f"standard deviations (Mahalanobis) from its mode, {np.linalg.norm(d[pos]):.0f} m in position): the reported "
        f"track is the most likely one moved by that shift, the posterior mean of {SAMPLES} samples (Metropolis "
        f"acceptance {rate:.2f}), with their covariance's departure from its "
        f"Gaussian model added to the Laplace covariances; position sigma along the major axis "
        f"{_major_sd(carried[0], pos):.0f} m (Laplace {_major_sd(P0, pos):.0f} m)"))
    return PosteriorSpread(states=shifted, covariances=carried, reason=reason)


def _own_model(icv: FloatArray, fallback: FloatArray) -> FloatArray:
    r"""The sampled cost's own Gaussian model of the first state, :math:`\mathbf C = \mathbf I_\mathrm{cv}^{-1}`.

    The samples' departure from it is what they add to the smoother's marginals (module docstring);
    ``fallback`` (the smoother's first covariance) where :math:`\mathbf I_\mathrm{cv}` is not positive definite.
    """
    try:
        own = np.asarray(np.linalg.inv(icv), dtype=float)
        np.linalg.cholesky(own)
    except np.linalg.LinAlgError:
        return fallback
    return own


def _major_sd(M: FloatArray, pos: slice) -> float:
    """Standard deviation along the major axis of ``M``'s position block."""
    return float(np.sqrt(max(float(np.max(np.linalg.eigvalsh(M[pos, pos]))), 0.0)))


def _information(model: TrackingModel, data: _Data, x0: FloatArray, huber_k: float | None,
                 fallback: FloatArray) -> FloatArray:
    r"""Gauss–Newton information of the sampled (deterministic) cost at ``x0``: :math:`\sum_j w_j\mathbf J_j^\top\mathbf J_j`.

    :math:`\mathbf J_j = \mathbf H(\mathbf F(t_j)\mathbf x_0)\,\mathbf F(t_j)/\sigma_j`, the measurement's
    whitened Jacobian with respect to the first state along the constant-velocity track, and :math:`w_j` the
    Huber weight of its residual (the smoother's IRLS weight; 1 for the Gaussian loss).  This is the quadratic
    model of the very cost the probe evaluates; the smoother's Laplace covariance, whose inverse it is compared
    with along the probe's axis, also holds the freedom that the process noise gives the track, which this
    cost does not (module docstring, "Where the process noise matters").  ``fallback`` where the Jacobian is
    undefined (a track through a sensor).
    """
    dt = np.asarray(data.t, dtype=float)
    try:
        h, H = model.observation.predict_and_jacobian(model.motion.propagate(x0, dt[:, None]), data.pair)
    except ValueError:
        return fallback
    r = (data.z - h) / data.sigma
    J = np.einsum("ij,ijk->ik", H, model.motion.F(dt)) / data.sigma[:, None]
    if not np.all(np.isfinite(J)):
        return fallback
    w = huber_weights(r, huber_k)
    return np.asarray(J.T @ (w[:, None] * J), dtype=float)


def _noise_share(model: TrackingModel, covariances: FloatArray, dt: FloatArray) -> float:
    r"""The largest eigenvalue of :math:`\mathbf L_k^{-1}\mathbf Q(\Delta t_k)\mathbf L_k^{-\top}` over ``k``.

    With :math:`\mathbf P_k = \mathbf L_k\mathbf L_k^\top` the covariances ``(n, d, d)`` and
    :math:`\Delta t_k` the times since the first measurement ``(n,)``: how much of each covariance, in its
    own standard deviations, the process noise since then could account for.  The samples of this module
    move the state deterministically, so they describe a posterior only while this is small.

    Raises
    ------
    numpy.linalg.LinAlgError
        A covariance that is not positive definite.
    """
    Li = np.linalg.inv(np.linalg.cholesky(covariances))
    noise = Li @ model.motion.Q(dt) @ np.swapaxes(Li, -1, -2)
    return float(np.max(np.linalg.eigvalsh(_symmetric(noise))))


def _carried(model: TrackingModel, laplace: FloatArray, excess: FloatArray, times: FloatArray,
             floor: float) -> FloatArray:
    r"""The smoother's Laplace marginals with the first state's sampled excess carried forward: ``(n, d, d)``.

    .. math::

        \mathbf P_k = \mathbf P^\mathrm L_k + \mathbf F(t_k - t_0)\,\mathbf E\,\mathbf F(t_k - t_0)^\top

    (module docstring), with ``laplace`` the stack :math:`\mathbf P^\mathrm L_k`, ``excess``
    :math:`\mathbf E` and ``times[0]`` the time :math:`t_0`.  The constant-velocity map stands in for the
    smoother's regression of :math:`\mathbf x_k` on :math:`\mathbf x_0`, which the marginals do not hold;
    where an :math:`\mathbf E` that is not positive semi-definite makes a matrix narrower than
    ``floor`` :math:`\times\,\mathbf P^\mathrm L_k` in some direction, its whitened eigenvalues against
    :math:`\mathbf P^\mathrm L_k` are raised to ``floor`` (at most 1): every matrix is positive
    definite, and none is narrowed by more than the samples narrowed their own Gaussian model.  A positive
    semi-definite :math:`\mathbf E` with ``floor`` 1 raises nothing.

    Raises
    ------
    numpy.linalg.LinAlgError
        If a Laplace covariance is not positive definite.
    """
    dt = np.asarray(times, dtype=float) - float(times[0])
    F = model.motion.F(dt)
    carried = laplace + F @ excess @ np.swapaxes(F, -1, -2)
    Li = np.linalg.inv(np.linalg.cholesky(laplace))
    lam, V = np.linalg.eigh(_symmetric(Li @ carried @ np.swapaxes(Li, -1, -2)))
    low = np.any(lam < floor, axis=-1)
    if np.any(low):
        L = np.linalg.inv(Li[low])
        raised = (V[low] * np.maximum(lam[low], floor)[..., None, :]) @ np.swapaxes(V[low], -1, -2)
        carried[low] = L @ raised @ np.swapaxes(L, -1, -2)
    return np.asarray(carried, dtype=float)


def _whitened_eigenvalues(P: FloatArray, S: FloatArray) -> FloatArray:
    r"""The eigenvalues of ``S`` whitened by ``P`` (positive definite), ascending: of
    :math:`\mathbf L^{-1}\mathbf S\mathbf L^{-\top}`, :math:`\mathbf P = \mathbf L\mathbf L^\top`; the smallest says
    how far ``S`` narrows ``P``, the largest how far it reaches beyond it."""
    Li = np.linalg.inv(np.linalg.cholesky(P))
    return np.asarray(np.linalg.eigvalsh(_symmetric(Li @ S @ Li.T)), dtype=float)


def _symmetric(M: FloatArray) -> FloatArray:
    """The symmetric part of a matrix or a stack of them."""
    return np.asarray(0.5 * (M + np.swapaxes(M, -1, -2)), dtype=float)


def _posterior(measurements: Measurements, model: TrackingModel, t0: float, huber_k: float | None, seed: int,
               samples: int) -> tuple[_Posterior, _Data]:
    """The posterior of the state at ``t0`` given ``measurements`` (times relative to ``t0``), ready to sample."""
    data = _Data(t=measurements.time - t0, pair=measurements.pair, z=measurements.doppler, sigma=measurements.sigma)
    return _Posterior(model, ParticleSettings(huber_k=huber_k, seed=seed, n_particles=samples), t0, data), data


def _sample_reaching(post: _Posterior, x0: FloatArray, P0: FloatArray, ratio: float, rng: np.random.Generator
                     ) -> tuple[FloatArray, float, str] | None:
    """:func:`_sample_about` of the smoother's first state, or :func:`_sample_broad` where the probe's
    ``ratio`` lies beyond :data:`BEND_LIMIT`, the narrow draw leaves fewer than :data:`ESS_MIN` effective samples
    or a probe from the narrow samples' spread reaches beyond :data:`GROWTH_LIMIT` times theirs (:func:`_growth`);
    with the words that say which ("" for the narrow proposal), or ``None`` when nothing can be drawn."""
    narrow = None
    if not 1.0 / BEND_LIMIT <= ratio <= BEND_LIMIT:
        why = "the valley bends far"
    else:
        narrow = _sample_about(post, x0, P0, SAMPLES, MOVES, rng)
        if narrow is None:
            return None
        if post.proposal_ess < ESS_MIN:
            why = f"a draw about the estimate left only {post.proposal_ess:.0f} effective samples"
        else:
            growth = _growth(post, x0, P0, narrow[0], rng)
            if growth <= GROWTH_LIMIT:
                return (*narrow, "")
            why = f"draws from the samples' own spread reached {growth:.1f} times their second moment"
    broad = _sample_broad(post, x0, P0, SAMPLES, MOVES, rng)
    if broad is None:  # no broad draw has a finite posterior: the narrow proposal's samples stand
        narrow = narrow if narrow is not None else _sample_about(post, x0, P0, SAMPLES, MOVES, rng)
        return None if narrow is None else (*narrow, "")
    second, rate, passes = broad
    return second, rate, (f"tempered from a proposal {2.0 * np.sqrt(BROAD):g} Laplace standard deviations wide "
                          f"and {passes} times more from the samples' own spread, as {why}; ")


def _growth(post: _Posterior, x0: FloatArray, P0: FloatArray, second: FloatArray, rng: np.random.Generator) -> float:
    r"""How much further than the samples a probe from their own spread reaches: :data:`GROWTH_LIMIT`'s statistic.

    :data:`PROBE_SAMPLES` are tempered into the posterior from :math:`\mathcal N(\bar{\mathbf x}, 4\,
    \mathrm{ADAPTED}\,\mathbf S)`, with :math:`\bar{\mathbf x}` and :math:`\mathbf S` the samples' mean and
    covariance, and moved :data:`PROBE_MOVES` times, then drawn again the same way from their own mean and
    covariance, :data:`PROBE_PASSES` passes in all.  The statistic is the largest eigenvalue of the last pass's
    second moment about ``x0`` whitened by ``P0`` over the same of ``second``, the samples' own.  The samples are
    left as they were; 1 where a pass draws nothing finite.
    """
    kept = post.x, post.logpost, post.label, post.s, post.logw  # sample_from binds new arrays: these stay intact
    try:
        for _ in range(PROBE_PASSES):
            if _from_own_spread(post, PROBE_SAMPLES, PROBE_MOVES, rng) is None:
                return 1.0
        return _reach(post, x0, P0) / float(_whitened_eigenvalues(P0, second)[-1])
    finally:
        post.x, post.logpost, post.label, post.s, post.logw = kept


def _second_moment(post: _Posterior, x0: FloatArray) -> FloatArray:
    r"""The samples' second moment about ``x0``, :math:`\frac1n\sum_i(\mathbf x_i - \mathbf x_0)(\mathbf x_i - \mathbf x_0)^\top`."""
    d = post.x - x0
    return np.asarray(d.T @ d / d.shape[0], dtype=float)


def _reach(post: _Posterior, x0: FloatArray, P0: FloatArray) -> float:
    """The largest eigenvalue of the samples' second moment about ``x0`` in the metric of ``P0``."""
    return float(_whitened_eigenvalues(P0, _second_moment(post, x0))[-1])


def _from_own_spread(post: _Posterior, samples: int, moves: int, rng: np.random.Generator) -> float | None:
    r"""One pass from the samples' own spread: ``samples`` tempered into the posterior from
    :math:`\mathcal N(\bar{\mathbf x}, 4\,\mathrm{ADAPTED}\,\mathbf S)`, the samples' mean and covariance, and
    moved ``moves`` times; the acceptance rate, or ``None`` (the samples unchanged) when nothing finite is drawn."""
    S = _weighted_cov(post.x, np.full(post.x.shape[0], 1.0 / post.x.shape[0]))
    return post.sample_from([(post.x.mean(axis=0), ADAPTED * S)], samples, moves, rng, tempered=True)


def _sample_about(post: _Posterior, x0: FloatArray, P0: FloatArray, samples: int, moves: int,
                  rng: np.random.Generator) -> tuple[FloatArray, float] | None:
    r"""Posterior samples from :math:`\mathcal N(\mathbf x_0, 4\mathbf P_0)`, resampled and moved; their second moment about ``x0``.

    Returns :math:`\frac1n\sum_i(\mathbf x_i - \mathbf x_0)(\mathbf x_i - \mathbf x_0)^\top` and the
    Metropolis acceptance rate, or ``None`` when no draw has a finite posterior.
    """
    rate = post.sample_from([(x0, P0)], samples, moves, rng, tempered=False)
    return None if rate is None else (_second_moment(post, x0), rate)


def _sample_broad(post: _Posterior, x0: FloatArray, P0: FloatArray, samples: int, moves: int,
                  rng: np.random.Generator) -> tuple[FloatArray, float, int] | None:
    r"""Posterior samples from the broad proposal, tempered in and followed along the valley; as :func:`_sample_about`.

    The samples start from :math:`\mathcal N(\mathbf x_0, 4\,\mathrm{BROAD}\,\mathbf P_0)` and are tempered
    into the posterior (:meth:`~fgdoppler.estimators.particle_posterior._Posterior.sample_from`) and moved,
    then drawn the same way from :math:`\mathcal N(\bar{\mathbf x}, 4\,\mathrm{ADAPTED}\,\mathbf S)`, the
    previous pass's mean and covariance: :data:`ADAPTED_PASSES` times, and more, up to
    :data:`MAX_ADAPTED_PASSES`, while the largest eigenvalue of the second moment about ``x0`` (in the metric of
    ``P0``) still grows by :data:`PASS_GROWTH` from one pass to the next.  A valley that reaches beyond the
    narrow proposal still gets its share of them, and each pass covers what the last found.

    Returns the second moment, the last moves' acceptance rate and the passes after the first, or ``None``
    when no draw has a finite posterior.
    """
    rate = post.sample_from([(x0, BROAD * P0)], samples, moves, rng, tempered=True)
    if rate is None:
        return None
    reach, passes = _reach(post, x0, P0), 0
    while passes < MAX_ADAPTED_PASSES:
        again = _from_own_spread(post, samples, moves, rng)
        rate = rate if again is None else again  # where nothing could be drawn the last pass's samples stand
        passes += 1
        reach, before = _reach(post, x0, P0), reach
        if passes >= ADAPTED_PASSES and reach < PASS_GROWTH * before:
            break
    return _second_moment(post, x0), rate, passes


def filtered_spread(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
                    covariances: FloatArray, usable: NDArray[np.bool_], *, interval: float, lag: float = 0.0,
                    huber_k: float | None = None, seed: int = 0,
                    reference: tuple[FloatArray, FloatArray] | None = None,
                    linearised_everywhere: bool = False) -> FilteredSpread | None:
    r"""A filter's covariances widened to enclose the posterior mean-square error sampled from the data so far.

    At a check at time :math:`t_c` (the module docstring, "Filtered
    covariances") the samples' second moment about the estimate, carried
    forward, is :math:`\mathbf S_c`; with :math:`\mathbf P_c = \mathbf L_c\mathbf L_c^\top`
    and :math:`\mathbf L_c^{-1}\mathbf S_c\mathbf L_c^{-\top} = \mathbf V\mathbf\Lambda\mathbf V^\top`,
    the widening :math:`\mathbf W_c = \mathbf V\mathbf\Lambda'\mathbf V^\top`,
    :math:`\lambda'_i = \lambda_i` where :math:`\lambda_i >` :data:`FILTER_WIDEN_MIN`
    and 1 elsewhere, applies to every later estimate up to the next check:
    :math:`\mathbf P_k \mapsto \mathbf L_k\mathbf W_c\mathbf L_k^\top`.

    Parameters
    ----------
    measurements
        The recording the filter ran on (the checks read those up to their time).
    model
        Observation, motion, prior and zone.
    times, states, covariances
        The filtered estimates ``(n,)``, ``(n, 2d)``, ``(n, 2d, 2d)``.
    usable
        ``(n,)``: where the covariance exists (``Estimates.cov_ok``); the others are left alone.
    interval
        Seconds between checks.
    lag
        Seconds of data after its time that an estimate has read (0 for a
        filter, the lag for a fixed-lag smoother's lagged estimates): a
        check at :math:`t_c` samples the posterior given the measurements
        up to :math:`t_c + \ell`.
    huber_k
        Huber threshold of the likelihood (``None``: Gaussian).
    seed
        Seed of the sampler.
    reference
        ``(times, states)`` of the offline smoother's track of the same
        recording, or ``None``.  Where a check finds the samples beyond their
        reach (the process noise since the first measurement, whitened by the
        estimate's covariance, above :data:`FILTER_NOISE_MAX`), up to the next
        check, and beyond :data:`MAX_SPAN` seconds of data, every covariance
        is widened the same way towards the posterior mean-square error of
        its estimate under the posterior of the data up to ``lag`` after its
        time linearised about this track
        (:mod:`~fgdoppler.estimators.linearized_posterior`, started from the
        first estimate and its widened covariance; for ``lag > 0`` that start
        has read the first lag's data, which the linearised posterior reads
        again: it is slightly too narrow there and widens a little less), at
        its own time.  Without it those covariances stand.
    linearised_everywhere
        With ``reference``: widen every usable covariance that way, after
        the sampled checks, not only those beyond the samples' reach.  The
        sampled checks are spaced (and back off) and carry one check's
        widening to the next; a covariance that changes shape between two
        checks can understate the error there, which the linearised
        posterior at each estimate's own time sees.  Every covariance then
        depends on the whole recording through the reference track (the
        point of linearisation; the posterior reads the data the estimate
        has read).

    Returns
    -------
    FilteredSpread or None
        The widened covariances, those of the sampled checks alone and the
        finding; ``None`` when nothing was widened.
    """
    if not (np.isfinite(lag) and lag >= 0.0):
        raise ValueError(f"lag must be a finite number >= 0, got {lag!r}")
    if len(measurements) == 0 or len(times) == 0:
        return None
    linear = None if reference is None else _Linearised(measurements, model, reference, huber_k, lag)
    out, checked, widened, checks, worst = _check_along(measurements, model, times, states, covariances, usable,
                                                        interval, lag, huber_k, seed, linear, linearised_everywhere)
    if widened == 0 and (linear is None or linear.widened == 0):
        return None
    return FilteredSpread(covariances=out, checked=checked,
                          reason=_spread_reason(lag, widened, checks, interval, linear, worst, linearised_everywhere))


def _check_along(measurements: Measurements, model: TrackingModel, times: FloatArray, states: FloatArray,
                 covariances: FloatArray, usable: NDArray[np.bool_], interval: float, lag: float,
                 huber_k: float | None, seed: int, linear: _Linearised | None, everywhere: bool = False
                 ) -> tuple[FloatArray, FloatArray | None, int, int, tuple[float, float, float, float]]:
    """The loop of :func:`filtered_spread`: (covariances, those before the linearised widening where it widened
    any, checks that widened, checks, the largest widening as (sd ratio, time, sampled sd, filter sd)); the
    linearised widening at every usable estimate with ``everywhere``, else beyond the samples' reach."""
    out = np.array(covariances, dtype=float, copy=True)
    t0 = float(np.min(measurements.time))
    widening: FloatArray | None = None
    next_check, quiet = -np.inf, 0  # quiet: checks in a row that widened nothing
    checks, widened, worst = 0, 0, (1.0, 0.0, 0.0, 0.0)  # (sd ratio, time, sampled sd, filter sd)
    pos = slice(0, model.dim)
    beyond = False  # the last check found the samples' deterministic motion unable to describe the posterior
    outside: list[int] = []  # the estimates beyond the samples' reach
    for k, t in enumerate(np.asarray(times, dtype=float)):
        if not usable[k]:
            continue
        P = out[k]
        if t - t0 > MAX_SPAN:
            widening, beyond = None, True
        elif t >= next_check:
            checks += 1
            reach = _samples_reach(model, P, t - t0)
            beyond = reach is False
            widening = _widening(measurements.between(t0, t + lag), model, t0, t, states[k], P, huber_k,
                                 np.random.default_rng([seed, checks])) if reach else None
            quiet = 0 if widening is not None else min(quiet + 1, FILTER_BACKOFF)
            next_check = t + max(interval * 2.0**quiet, 0.1 * (t - t0))
            if widening is not None:
                widened += 1
                worst = max(worst, _sd_ratio(P, _whitened_apply(P, widening), pos, t))
        if beyond or everywhere:
            outside.append(k)
        if not beyond and widening is not None:
            out[k] = _whitened_apply(P, widening)
    checked = None
    if linear is not None and outside:
        before = out.copy()
        first = int(np.flatnonzero(usable)[0])
        worst = max(worst, linear.widen(out, np.asarray(times, dtype=float), states, np.array(outside), first))
        checked = before if linear.widened else None
    return out, checked, widened, checks, worst


def _spread_reason(lag: float, widened: int, checks: int, interval: float, linear: _Linearised | None,
                   worst: tuple[float, float, float, float], everywhere: bool = False) -> Reason:
    """The informational ``nonlinear`` finding of :func:`filtered_spread`: what was widened, how, and where most."""
    what = "filtered covariances" if lag == 0.0 else "lagged covariances"
    seen = "the data so far" if lag == 0.0 else f"the data up to {lag:g} s later"
    parts = []
    if widened:
        parts.append(f"to enclose posterior samples of {seen} at {widened} of {checks} checks ({FILTER_SAMPLES} "
                     f"samples each, every {interval:g} s or more)")
    if linear is not None and linear.widened:
        parts.append(f"{'and ' if widened else ''}to the posterior of {seen} linearised about the offline "
                     f"smoother's track at {linear.widened} of the {linear.times} times "
                     + ("checked" if everywhere else "beyond the samples' reach (the process noise)"))
    return Reason(code="nonlinear", status="ok", message=(
        f"{what} widened {' '.join(parts)}: the Gaussian covariance understated "
        f"the uncertainty; most at t = {worst[1]:.1f} s, position sigma along the major axis {worst[2]:.0f} m "
        f"where the {'filter' if lag == 0.0 else 'smoother'} said {worst[3]:.0f} m"))


class _Linearised:
    """The posterior of the data an estimate has read, linearised about a reference track
    (:mod:`~fgdoppler.estimators.linearized_posterior`), for :func:`filtered_spread` beyond the samples' reach,
    counting the estimates it was asked about and widened."""

    def __init__(self, measurements: Measurements, model: TrackingModel, reference: tuple[FloatArray, FloatArray],
                 huber_k: float | None, lag: float) -> None:
        self.measurements, self.model, self.reference, self.huber_k = measurements, model, reference, huber_k
        self.lag = lag
        self.times = 0
        self.widened = 0

    def widen(self, out: FloatArray, times: FloatArray, states: FloatArray, at: NDArray[np.intp],
              first: int) -> tuple[float, float, float, float]:
        r"""Widen ``out[at]`` in place towards the posterior mean-square error of ``states[at]`` given the data up
        to ``lag`` after their times (:func:`_widened_stack` with :data:`FILTER_WIDEN_MIN`), the linearised
        filter started from estimate ``first`` and ``out[first]``.

        Nothing is widened where the model is undefined at the reference (a track through a sensor) or the
        recursion breaks down.  Returns the largest widening as :func:`_sd_ratio` does (ratio 1: none).
        """
        worst = (1.0, 0.0, 0.0, 0.0)
        t_start = float(times[first])
        try:
            post = linearized_filter(self.measurements, self.model, *self.reference, t_start, states[first],
                                     out[first], self.huber_k)
        except (ValueError, np.linalg.LinAlgError):
            return worst
        if not all(np.all(np.isfinite(v)) for v in (post.means, post.covariances, post.gains)):
            return worst
        at = at[times[at] >= t_start]
        means, covs = post.at(times[at], times[at] + self.lag)
        self.times += at.size
        P = out[at]
        wide, grew = _widened_stack(P, mean_square_errors(states[at], means, covs), FILTER_WIDEN_MIN)
        if not np.any(grew):
            return worst
        self.widened += int(np.count_nonzero(grew))
        out[at[grew]] = wide[grew]
        return max(worst, *_sd_ratios(P[grew], wide[grew], slice(0, self.model.dim), times[at[grew]]))


def _samples_reach(model: TrackingModel, P: FloatArray, dt: float) -> bool | None:
    """Whether the process noise over ``dt`` seconds, whitened by ``P``, stays within :data:`FILTER_NOISE_MAX`
    (:func:`_noise_share`): the samples' deterministic motion still describes the posterior (``None``: ``P`` is
    not positive definite, and the check is skipped)."""
    try:
        return _noise_share(model, P[None], np.array([dt])) <= FILTER_NOISE_MAX
    except np.linalg.LinAlgError:
        return None


def _widening(measurements: Measurements, model: TrackingModel, t0: float, t: float, x: FloatArray, P: FloatArray,
              huber_k: float | None, rng: np.random.Generator) -> FloatArray | None:
    r"""The whitened widening :math:`\mathbf W_c` of :func:`filtered_spread` at one check (``None``: none)."""
    if len(measurements) == 0:
        return None
    try:
        Fi = model.motion.F(t0 - t)
        x0 = Fi @ x
        P0 = Fi @ P @ Fi.T
        post, _ = _posterior(measurements, model, t0, huber_k, 0, FILTER_SAMPLES)
        drawn = _sample_about(post, x0, 0.5 * (P0 + P0.T), FILTER_SAMPLES, FILTER_MOVES, rng)
        if drawn is None:
            return None
        F = model.motion.F(t - t0)  # a filter has no smoothed marginals: the process noise unconditioned
        return _whitened_widening(P, F @ drawn[0] @ F.T + model.motion.Q(t - t0), FILTER_WIDEN_MIN)
    except np.linalg.LinAlgError:
        return None


def _sd_ratio(P: FloatArray, S: FloatArray, pos: slice, t: float) -> tuple[float, float, float, float]:
    """(ratio of the major-axis position sigmas, ``t``, sigma of ``S``, sigma of ``P``)."""
    return _sd_ratios(P[None], S[None], pos, np.array([t]))[0]


def _sd_ratios(P: FloatArray, S: FloatArray, pos: slice, t: FloatArray) -> list[tuple[float, float, float, float]]:
    """:func:`_sd_ratio` of stacks ``(n, d, d)`` at times ``(n,)``."""
    sd_s = np.sqrt(np.max(np.linalg.eigvalsh(S[:, pos, pos]), axis=-1))
    sd_p = np.sqrt(np.max(np.linalg.eigvalsh(P[:, pos, pos]), axis=-1))
    return [(float(a / b), float(tk), float(a), float(b)) for a, b, tk in zip(sd_s, sd_p, t, strict=True)]


def _whitened_apply(P: FloatArray, widening: FloatArray) -> FloatArray:
    r""":math:`\mathbf L\mathbf W\mathbf L^\top` with :math:`\mathbf P = \mathbf L\mathbf L^\top` (one matrix or a stack).

    Raises
    ------
    numpy.linalg.LinAlgError
        If a ``P`` is not positive definite.
    """
    L = np.linalg.cholesky(P)
    out = L @ widening @ np.swapaxes(L, -1, -2)
    return _symmetric(out)


def _widened_stack(P: FloatArray, S: FloatArray, min_ratio: float) -> tuple[FloatArray, NDArray[np.bool_]]:
    r"""Each of the stack ``P`` ``(n, d, d)`` widened towards its ``S`` (:func:`_whitened_widenings`) and which were.

    A ``P`` that is not positive definite (or whose whitened ``S`` has no
    eigendecomposition) is left as it is; the stack is halved until the
    failure is isolated, so one bad matrix costs :math:`O(\log n)` retries.
    """
    try:
        widening, grew = _whitened_widenings(P, S, min_ratio)
        return np.where(grew[:, None, None], _whitened_apply(P, widening), P), grew
    except np.linalg.LinAlgError:
        if len(P) == 1:
            return P.copy(), np.zeros(1, dtype=bool)
        half = len(P) // 2
        (a, ga), (b, gb) = _widened_stack(P[:half], S[:half], min_ratio), _widened_stack(P[half:], S[half:], min_ratio)
        return np.concatenate([a, b]), np.concatenate([ga, gb])


def _enclosing(laplace: FloatArray, sampled: FloatArray) -> FloatArray:
    r"""The smallest-in-each-direction covariance at least as large as both (whitened eigenvalues ``max(λ, 1)``).

    With :math:`\mathbf P = \mathbf L\mathbf L^\top` and
    :math:`\mathbf L^{-1}\mathbf S\mathbf L^{-\top} = \mathbf V\mathbf\Lambda\mathbf V^\top`,
    returns :math:`\mathbf L\mathbf V\max(\mathbf\Lambda, \mathbf I)\mathbf V^\top\mathbf L^\top`.
    The samples only ever widen the Laplace covariance: where they are
    narrower the posterior may have mass the sampler (started at the
    estimate) did not reach, and a covariance that is too small is the
    failure this module exists to prevent.
    """
    widening = _whitened_widening(laplace, sampled, 1.0)
    return laplace if widening is None else _whitened_apply(laplace, widening)


def _whitened_widening(P: FloatArray, S: FloatArray, min_ratio: float) -> FloatArray | None:
    r"""The whitened widening :math:`\mathbf V\mathbf\Lambda'\mathbf V^\top` of ``P`` towards ``S`` (``None``: none).

    One matrix of :func:`_whitened_widenings`.

    Raises
    ------
    numpy.linalg.LinAlgError
        If ``P`` is not positive definite.
    """
    widening, grew = _whitened_widenings(P[None], S[None], min_ratio)
    return widening[0] if grew[0] else None


def _whitened_widenings(P: FloatArray, S: FloatArray, min_ratio: float) -> tuple[FloatArray, NDArray[np.bool_]]:
    r"""The whitened widenings :math:`\mathbf V\mathbf\Lambda'\mathbf V^\top` of a stack ``P`` towards ``S``
    ``(n, d, d)`` and which of them widen anything.

    With :math:`\mathbf P = \mathbf L\mathbf L^\top` and
    :math:`\mathbf L^{-1}\mathbf S\mathbf L^{-\top} = \mathbf V\mathbf\Lambda\mathbf V^\top`,
    :math:`\lambda'_i = \lambda_i` where :math:`\lambda_i >` ``min_ratio`` and 1
    elsewhere; ``min_ratio = 1`` gives :math:`\max(\mathbf\Lambda, \mathbf I)`.
    NumPy's stacked factorisations run the same LAPACK routine on each
    matrix, so a stack gives bit for bit what each matrix alone does.

    Raises
    ------
    numpy.linalg.LinAlgError
        If a ``P`` is not positive definite.
    """
    Li = np.linalg.inv(np.linalg.cholesky(P))
    M = Li @ S @ np.swapaxes(Li, -1, -2)
    lam, V = np.linalg.eigh(_symmetric(M))
    grow = np.isfinite(lam) & (lam > min_ratio)
    widening = (V * np.where(grow, lam, 1.0)[..., None, :]) @ np.swapaxes(V, -1, -2)
    return np.asarray(widening, dtype=float), np.any(grow, axis=-1)
