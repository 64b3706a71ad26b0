#!/usr/bin/env bash
# The paper's Table 2 rows we can run, in one go: cGNN/MSM, noCond/MSM and cGNN/aug MSM on the
# full MSM set (100 locations x 11 directions, 7:2:1 by location), then cGNN/Exp on a default
# twin session over 5 folds (12:3:5 by press) without and with transfer learning from the aug
# MSM model. Settings through the environment:
#   OUT (out/table2)  EPOCHS_MSM (250)  EPOCHS_EXP (250)  LR_MSM (1e-4)  LR_EXP (1e-4)
#   DEVICE (auto)  LOCATIONS (100)  DIRECTIONS (11)  SEED (0)  STAGE (all | msm | exp | eval)
#   PIPELINE (pipeline; e.g. "python -m pipeline" where the package is not installed)
# A run folder that exists is resumed, so the script can be stopped and started again.
set -euo pipefail
OUT=${OUT:-out/table2}; SEED=${SEED:-0}; DEVICE=${DEVICE:-auto}; STAGE=${STAGE:-all}
EM=${EPOCHS_MSM:-250}; EE=${EPOCHS_EXP:-250}; LM=${LR_MSM:-1e-4}; LE=${LR_EXP:-1e-4}
P="${PIPELINE:-pipeline} -q"
mkdir -p "$OUT"
if [ "$STAGE" = all ] || [ "$STAGE" = msm ]; then
  [ -f "$OUT/msm.h5" ] || $P simulate --out "$OUT/msm.h5" --locations "${LOCATIONS:-100}" \
      --directions "${DIRECTIONS:-11}" --seed "$SEED" --no-rrd
  [ -f "$OUT/msm_splits.json" ] || $P split "$OUT/msm.h5" --out "$OUT/msm_splits.json" --folds 1 --seed "$SEED" --no-rrd
  M="--data $OUT/msm.h5 --splits $OUT/msm_splits.json --epochs $EM --lr $LM --device $DEVICE --seed $SEED --no-rrd"
  $P train $M --out "$OUT/runs/msm"
  $P train $M --out "$OUT/runs/msm_nocond" --no-cond
  $P train $M --out "$OUT/runs/msm_aug" --point-fraction 0.1
fi
if [ "$STAGE" = all ] || [ "$STAGE" = exp ]; then
  if [ ! -f "$OUT/states.h5" ]; then
    $P synth "$OUT/session" --seed "$SEED"
    $P ingest "$OUT/session" --out "$OUT/session.mcap" --no-rrd
    $P sync "$OUT/session.mcap" --out "$OUT/synced.h5" --no-rrd
    $P extract "$OUT/synced.h5" --out "$OUT/states.h5" --seed "$SEED" --no-rrd
    $P split "$OUT/states.h5" --out "$OUT/splits.json" --seed "$SEED" --no-rrd
  fi
  E="--data $OUT/states.h5 --splits $OUT/splits.json --epochs $EE --lr $LE --device $DEVICE --seed $SEED --no-rrd"
  for k in 0 1 2 3 4; do
    $P train $E --fold $k --out "$OUT/runs/exp_fold$k"
    $P train $E --fold $k --out "$OUT/runs/exp_tl_fold$k" --init "$OUT/runs/msm_aug/best.pt"
  done
fi
if [ "$STAGE" = all ] || [ "$STAGE" = eval ]; then
  $P eval "$OUT"/runs/msm "$OUT"/runs/msm_nocond "$OUT"/runs/msm_aug "$OUT"/runs/exp_fold* \
      "$OUT"/runs/exp_tl_fold* --out "$OUT/metrics.json" --device "${EVAL_DEVICE:-cpu}" --no-rrd
  cat "$OUT/metrics.md"
fi
