""":func:`refine`: prepare, the noise model, the gates, the solution epoch moved to the refined
orbit's own traverse point, the circular-constraint test, the outputs.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from trackproc.errors import ProcessingError
from trackproc.models import modifiers as md
from trackproc.pipeline.refine.assemble import prepare
from trackproc.methods.estimation import prior as pr
from trackproc.pipeline.od import decision as od_decision
from trackproc.pipeline.refine.gates import (circular_consistency, may_refuse, solve_gated, solve_weighted,
                                            stale_improvement, with_noise_of)
from trackproc.pipeline.refine.noise import solve_noise
from trackproc.pipeline.refine.options import MAX_TRAVERSE_ITERATIONS, TRAVERSE_TOLERANCE_S, RefineOptions, RefineResult
from trackproc.pipeline.refine.result import finish
from trackproc.pipeline.refine.second_signal import (annotate, declined_signal, find_second_signal, public,
                                                    refine_edited)
from trackproc.pipeline.refine.steps import as_kind, declined_step, scan_steps, shifted, step_modifier
from trackproc.pipeline.refine.traverse import model_traverse, time_tag_covariance
from trackproc.types import PassTable


def refine(table: PassTable, initial, stations=None, options: RefineOptions | None = None, eop=None,
           source: str = "<pass>", _modelled_step: dict | None = None, _second_signal: dict | None = None,
           _noise_of=None) -> RefineResult:
    """Refine ``initial`` (a GCRF :class:`~trackproc.io.statefile.State`, or a TLE's) from one pass.

    The consistency gates (docs/refine.md, "Quality"): the a-priori is scaled by its variance
    component when the pass contradicts it (:func:`solve_adapted`); the solution epoch follows the
    refined orbit's own zero range-rate; and when the pass cannot improve the stale state
    (an a-priori conflict the pass cannot carry, or one on residuals correlated beyond the pass's noise model), the
    stale state is kept with its covariance (``refused`` in the diagnostics and the quality).
    The result's ``quality`` (:func:`refine_quality`) says what was found. A level shift inside the
    pass (:func:`~trackproc.pipeline.refine.steps.scan_steps`) is modelled from the detected sample
    on when it is one of the transmitter's frequency (the pass refined again with a ``doppler_step``;
    ``_modelled_step`` is that detection), and declines the pass when it is a jump of the time tags
    or the step model does not remove it (``step`` in the diagnostics and the quality). Samples of a
    second signal (:mod:`~trackproc.pipeline.refine.second_signal`) are edited out and the pass refined
    again with the same noise model (``_second_signal`` those samples, ``_noise_of`` the first
    refinement), or the pass declined when that does not free it (``second_signal``).

    Returns :class:`RefineResult`; raises :class:`InputError` (exit 2) for invalid input and
    :class:`ProcessingError` (exit 1) when the refinement fails (no convergence, rank deficiency).

    Over 100 lines: its steps are functions (prepare, solve_noise, solve_gated, scan_steps,
    model_traverse, the decision, finish); what stays is their order and what each hands the next
    (a refusal stops the traverse re-solves, a modelled step re-runs the whole refinement).
    """
    opt = options or RefineOptions()
    ref = prepare(table, initial, stations, opt, eop, source)
    # the pass's noise model (REML) and transmitter drift first, then the gates on that solution
    if _noise_of is not None:                           # a second signal edited out: the noise model stands
        ref = with_noise_of(ref, _noise_of, same_samples=False)
        sol, kkt, scale = solve_weighted(ref)
    else:
        ref, sol, kkt, scale = solve_noise(table, initial, ref, stations, eop, source)
    epoch0 = ref.problem.epoch                          # the epoch a modelled step's time is counted from
    first = (ref, sol, kkt, scale)
    gated = solve_gated(ref, first=(sol, kkt, scale))
    ref, sol, kkt, scale = gated.solved
    adaptation, improvement, refusal = gated.adaptation, gated.improvement, gated.refusal
    # a gross error inside the pass (an oscillator step, a time-tag jump): modelled or declined. The
    # scan reads the gated solution (a default a-priori the pass contradicts is adapted first, so
    # that its conflict is not taken for a step), or the first one when the gates kept the stale state
    step, declined = None, None
    scanned = (ref, sol, kkt, scale) if refusal is None else first
    # a one-way link's transmitter (an offset to step); the gates' own refusal stands unless a
    # frequency step explains it
    scan = (scan_steps(*scanned) if opt.cost == "pointwise" and not opt.circular
            and first[0].modifier_drivers(md.DopplerOffset) else None)
    if scan is not None and refusal is not None and _modelled_step is None and scan["kind"] != "frequency":
        scan = None
    # another emitter tracked for part of the pass: edit its samples out and refine again, or decline.
    # A level shift the scan finds goes first: a trimmed white refit reads a frequency step as runs
    signal = (find_second_signal(*scanned[:2]) if _modelled_step is None and not (scan or {}).get("significant")
              else None)
    if signal is not None and signal["found"]:
        if _second_signal is None:
            edited = refine_edited(refine, table, initial, stations, opt, eop, source, ref, signal)
            if edited is not None:
                return edited
        if may_refuse(first[0]):
            declined = declined_signal(first[0], signal, _second_signal)
            ref, sol, kkt, scale = first
            improvement = stale_improvement(ref, sol, scale) if ref.priors else None
            return annotate(finish(ref, sol, kkt, scale, improvement=improvement, refusal=declined,
                                   decision=declined["decision"]),
                            {"action": "declined", "check": public(signal), "edited": public(_second_signal)})
    said = None if signal is None else {"action": "said" if signal["found"] else "none", "check": public(signal)}
    if _modelled_step is not None:
        step = {"action": "modelled", "modelled": _modelled_step,
                "parameter": ref.modifier_drivers(md.DopplerStep)[0].name, "scan": scan}
        if scan is not None and scan["significant"] and may_refuse(first[0]):
            step["action"] = "declined"
            declined = declined_step(first[0], scan, modelled=_modelled_step)
    elif scan is not None and scan["significant"]:
        step = {"action": "said", "scan": scan}
        freq = as_kind(scan, "frequency")
        if scan["kind"] == "frequency" and ref.modifier_drivers(md.DopplerOffset):
            # an offset change is exactly a step of the offset: model it, and let the scan of the
            # re-solved pass say whether that explains it; a shift that fits a jump of the time tags
            # better is declined (either side may be the wrongly tagged one)
            try:
                stepped = refine(table, initial, stations,
                                 replace(opt, modifiers=tuple(opt.modifiers) + (step_modifier(ref, freq),)), eop,
                                 source, _modelled_step=freq, _second_signal=_second_signal, _noise_of=_noise_of)
                if refusal is None or (stepped.state.diagnostics.get("step") or {}).get("action") != "declined":
                    return annotate(stepped, said)
                step = None                              # the gates' own refusal stands
            except ProcessingError:
                pass                                     # the step model does not converge: decline below
        if step is not None and refusal is None and may_refuse(first[0]):
            step["action"] = "declined"
            declined = declined_step(first[0], scan)
    if declined is not None:
        ref, sol, kkt, scale = first
        improvement = stale_improvement(ref, sol, scale) if ref.priors else None
        return annotate(finish(ref, sol, kkt, scale, improvement=improvement, refusal=declined,
                               decision=declined["decision"], step=step), said)
    # the solution epoch is the refined orbit's own traverse point: re-solve there until it stays
    moves = []
    for _ in range(MAX_TRAVERSE_ITERATIONS if refusal is None else 0):
        t_model = model_traverse(ref, sol.values)
        if t_model is None or abs(t_model) <= TRAVERSE_TOLERANCE_S:
            break
        epoch = ref.problem.epoch + np.timedelta64(int(round(t_model * 1e9)), "ns")
        try:
            # the same transmitter model (a drift the pass wanted) and a noise model refitted there
            bias = "offset+drift" if ref.modifier_drivers(md.DopplerDrift) else opt.doppler_bias
            later = float((epoch - epoch0) / np.timedelta64(1, "ns")) * 1e-9
            moved = prepare(table, initial, stations, replace(opt, traverse_epoch=epoch, doppler_bias=bias,
                                                              modifiers=shifted(opt.modifiers, later)), eop,
                            source, curve=ref.curve, like=ref)
            moved.warnings[:] = list(ref.warnings)
            moved = with_noise_of(moved, ref)
            first = solve_weighted(moved)
            factor = adaptation["factor"] if adaptation else 1.0
            moved_gated = solve_gated(moved, factor, first=tuple(first) if factor == 1.0 else None)
        except ProcessingError:
            break                                        # the quality reports the mismatch left
        moves.append(float(t_model))
        ref, sol, kkt, scale = moved_gated.solved
        adaptation, improvement, refusal = moved_gated.adaptation, moved_gated.improvement, moved_gated.refusal
        if refusal is not None:
            break
    decision = None
    if refusal is None and may_refuse(ref):
        # replace the stale state only when the refined one is expected to predict better
        npb = ref.n_problem
        cov = np.asarray(ref.covariance(sol, kkt), float)
        tt_sigma, _ = ref.time_tag_sigma()
        if tt_sigma > 0:
            # the station's time-tag uncertainty (consider) is in the covariance written: judge with it
            extra = time_tag_covariance(ref, sol.values, cov, tt_sigma)
            cov = cov + extra if extra is not None else cov
        made = od_decision.by_prediction(ref.problem, np.asarray(sol.values, float)[:npb], cov[:npb, :npb],
                                         ref.priors, opt.horizon_days, ref.apriori_source or None)
        if made is not None:
            decision = made.as_dict()
            if adaptation is not None and adaptation.get("factor", 1.0) > 1.0:
                decision["apriori_adapted"] = True       # the default a-priori, loosened to the pass
            if made.keeps_prior:
                refusal = {"code": "kept", "reason": made.reason, "decision": decision,
                           "state_covariance": pr.state_prior_covariance(ref.priors)}
    consistency = None
    if ref.options.circular:
        # the same assembled problem without the constraints and r_ka (always the last parameter)
        free = replace(ref, options=replace(ref.options, circular=False), names=ref.names[:-1], x0=ref.x0[:-1],
                       scales=ref.scales[:-1])
        consistency = circular_consistency(free, sol, scale)
    return annotate(finish(ref, sol, kkt, scale, consistency=consistency, adaptation=adaptation,
                           traverse_moves=moves, improvement=improvement, refusal=refusal,
                           decision=decision if refusal is None else refusal.get("decision"), step=step), said)
