# The device command behind docs/performance-gpu.md (the device tool's run, carry [".gpu"]): here first
#   echo /.gpu/ >> .git/info/exclude; python benchmarks/device/gpu_bench.py pack .gpu/volumes
#   pip download --no-deps -d .gpu/whl pydicom==3.0.2
# then on the device: the real-GPU checks of the CUDA ray caster and of the CUDA TAAU, layered TAAU, XS filter, XS
# pipeline and the bench's methods on the device (the tests' scripts, their differences printed), the device-resident projection (gpu_probe.py: the parts
# timed on the GPU, the CPU runs' PSNRs placed at those times) within PROBE_S seconds, then volsr bench on CUDA (RUNS,
# e.g. 512/2,1024/2; RUNS= for none) within BENCH_S seconds. Every step also ends by TOTAL_S seconds after the start
# (default 540), so the whole command fits the device tool's timeout_s whatever the steps take. CHECKS names the
# checks to run (default render,temporal; CHECKS= for none), PROBE_ARGS adds to the probe's (e.g. --sizes 1024).
set -o pipefail; export PYTHONUNBUFFERED=1; S=/tmp/site; END=$((SECONDS + ${TOTAL_S:-540}))
left() { local rest=$((END - SECONDS)); echo $((rest < $1 ? (rest > 1 ? rest : 1) : $1)); }
python3 -m pip install -q --no-index --no-deps --no-compile --no-build-isolation --target $S .gpu/whl/*.whl . \
    >/tmp/install.log 2>&1 || { tail -20 /tmp/install.log; exit 1; }
rm -rf build; export PYTHONPATH=$S
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; nproc
python3 -c "import numpy, numba, numba_cuda, torch; print(numpy.__version__, numba.__version__, numba_cuda.__version__, torch.__version__)"
# the checks run from /tmp: from the repository's root its volsr_core folder would shadow the installed package
R=$PWD; cd /tmp; CHECKS=${CHECKS-render,temporal}
[[ $CHECKS != *render* ]] || VOLSR_TEST_REAL_CUDA=1 timeout $(left 200) python3 -c "import sys, types; sys.modules['SimpleITK'] = types.ModuleType('SimpleITK')
sys.path.insert(0, '$R/tests'); import test_render_cuda as t; exec(t.SCRIPT.format(tests='$R/tests'))" 2>&1 | tee $OUT/cuda_check.log
[[ $CHECKS != *temporal* ]] || VOLSR_TEST_REAL_CUDA=1 timeout $(left 200) python3 -c "import sys, types; sys.modules['SimpleITK'] = types.ModuleType('SimpleITK')
sys.path.insert(0, '$R/tests'); import test_temporal_cuda as m; [exec(s, {}) for s in (m.SCRIPT, m.PIPELINE, m.METHODS)]" \
    2>&1 | grep -v Warning | tee $OUT/temporal_cuda_check.log; cd $R
timeout $(left ${PROBE_S:-150}) python3 benchmarks/device/gpu_probe.py $OUT/probe --volumes .gpu/volumes ${PROBE_ARGS-} 2>&1 | tee $OUT/probe.log
[ -z "${RUNS-512/2,1024/2}" ] || timeout $(left ${BENCH_S:-320}) python3 benchmarks/device/gpu_bench.py run $OUT \
    ${RUNS-512/2,1024/2} --volumes .gpu/volumes 2>&1 | tee $OUT/bench.log | grep -v "bench:"
