source /work/main/scripts/env.sh
export PYTHONPATH=/work/wt13/src/uam_sim:/work/wt13/src/uam_planner:/work/wt13/src/uam_solvers:/work/wt13/src/uam_contract:$PYTHONPATH
