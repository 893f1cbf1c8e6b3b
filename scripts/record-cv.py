#!/usr/bin/env python3
"""Records a cross-validation result in a model card, as the metric the model's recipe reaches.

Usage: scripts/record-cv.py models/<name> runs/cv/<run>[/kept-eval.json] "<command that produced the run>"
Adds (or replaces) cv_mean_error_known_k, cv_median_error_known_k, cv_mean_error_sod and
cv_k_correct_sod, computed with the same training recipe on leave-one-out folds.
"""
import json
import pathlib
import sys

model, run, command = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2]), sys.argv[3]
card_path = model / "model.json"
card = json.loads(card_path.read_text())
# A cv run's summary.json, or the totals file of scripts/cv-eval-kept.sh / cv-ensemble.sh.
t = json.loads((run if run.is_file() else run / "summary.json").read_text())["totals"]
protocol = f"leave-one-sequence-out, {t['samples']} folds, same recipe as this model ({run.parent.name if run.is_file() else run.name})"
new = {
    "cv_mean_error_known_k": t["known"]["mean_error"],
    "cv_median_error_known_k": t["known"]["median_error"],
    "cv_mean_error_sod": t["sod"]["mean_error"],
    "cv_k_correct_sod": t["sod"]["k_correct"],
}
card["metrics"] = [m for m in card.get("metrics", []) if m["name"] not in new]
card["metrics"] += [{"name": k, "value": v, "protocol": protocol, "command": command} for k, v in new.items()]
card_path.write_text(json.dumps(card, indent=2) + "\n")
print(f"{card_path}: recorded {', '.join(new)}")
