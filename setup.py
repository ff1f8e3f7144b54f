"""VolSR: learned super-resolution for medical direct volume rendering."""
from setuptools import find_packages, setup

setup(
    name="volsr",
    version="0.1.0",
    description="Learned super-resolution for direct volume rendering of medical volumes",
    long_description=open("README.md", encoding="utf-8").read(),
    long_description_content_type="text/markdown",
    python_requires=">=3.10",
    packages=find_packages(include=["volsr_core", "volsr_core.*"]) + ["volsr_core.resources"],
    package_dir={"volsr_core.resources": "resources"},
    package_data={"volsr_core.resources": ["presets/*.json", "schemas/*.json", "models/*"]},
    install_requires=[
        "numpy>=1.24",
        "numba>=0.59",
        "SimpleITK>=2.2",
        "pydicom>=2.4",
        "tqdm>=4.60",
        "pyyaml>=6.0",
        "pillow>=9.0",
        "h5py>=3.8",
        "jsonschema>=4.0",
    ],
    extras_require={
        # Hosts bring their own VTK (Slicer, ParaView): never a hard dependency.
        "vtk": ["vtk>=9.3"],
        "pyvista": ["pyvista>=0.43"],
        "torch": ["torch>=2.6,<3", "scikit-image>=0.22", "matplotlib>=3.7"],
        "onnx": ["onnxruntime>=1.17", "onnx>=1.17", "onnxscript>=0.5"],  # onnxscript: export (with torch)
        # numba-cuda up to 0.30 overloads np.row_stack, which NumPy 2.5 removed; render/cuda.py gives NumPy the name
        # back before importing it (seen compiling and matching the CPU on the lent H200: NumPy 2.5.2, numba-cuda 0.30.4)
        "cuda": ["numba-cuda>=0.20,<0.31"],
        "video": ["imageio>=2.30", "imageio-ffmpeg>=0.4"],  # volsr upscale --video (MP4 through ffmpeg)
        # NVRTC and NVVM (no driver, no GPU): numba-cuda compiles the CUDA kernels to PTX in the tests
        "dev": ["pytest>=8", "pytest-xdist>=3", "scikit-image>=0.22", "matplotlib>=3.7", "numba-cuda>=0.20",
                "nvidia-cuda-nvrtc-cu12>=12.4", "nvidia-cuda-nvcc-cu12>=12.4"],
    },
    entry_points={"console_scripts": ["volsr=volsr_core.cli:main"]},
)
