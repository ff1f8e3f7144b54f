"""Index layout of the small arrays the ray-cast kernels take, shared by CPU and CUDA builds.

Kernels get plain arrays (Numba compiles them for the CPU and for CUDA alike); these constants
name their slots. Read as compile-time constants by Numba.
"""

# cam: float64[CAM_SIZE], the current camera in world mm (LPS) --------------------------------
CAM_POS = 0          # 3: camera position
CAM_RIGHT = 3        # 3: unit right vector
CAM_UP = 6           # 3: unit up vector
CAM_FWD = 9          # 3: unit direction of projection
CAM_HALF_W = 12      # half-width of the view: tan(angle/2)*aspect (perspective) or parallel_scale*aspect (mm)
CAM_HALF_H = 13      # half-height: tan(angle/2) or parallel_scale (mm)
CAM_PARALLEL = 14    # 1.0 for parallel projection
CAM_NEAR = 15        # clipping range along the view direction, mm
CAM_FAR = 16
CAM_JITTER_X = 17    # sub-pixel offset of every ray, pixels, +x right
CAM_JITTER_Y = 18    # +y down
CAM_DEPTH_LO = 19    # view depth (mm) mapped to quasi-depth 0 (front of the volume's bounding sphere)
CAM_DEPTH_SPAN = 20  # view depth span (mm) mapped to [0, 1] (the sphere's diameter)
CAM_FOCAL_DEPTH = 21 # view depth (mm) of the focal plane: where background pixels put their point
CAM_SLAB_NEAR = 22   # view depth (mm) where depth slab 0 begins (the visible bounds' front, within the clipping range)
CAM_SLAB_SPAN = 23   # view depth span (mm) cut into P_SLABS equal slabs
CAM_SIZE = 24

# params: float64[PARAM_SIZE], sampling, classification and lighting ---------------------------
P_STEP = 0           # sample distance, mm
P_ERT = 1            # early ray termination threshold on accumulated alpha
P_AMBIENT = 2
P_DIFFUSE = 3
P_SPECULAR = 4
P_SPEC_POWER = 5
P_SHADE = 6          # 1.0 when shading is on
P_GRAD_OPACITY = 7   # 1.0 when a gradient-opacity function applies
P_LUT_X0 = 8         # value at LUT entry 0
P_LUT_INV_DX = 9     # LUT entries per value unit
P_GLUT_INV_DX = 10   # gradient-opacity LUT entries per (value unit / mm)
P_BG_R = 11          # background colour
P_BG_G = 12
P_BG_B = 13
P_START_JITTER = 14  # offset each ray's first sample by a fraction of the step: 1.0 hashed white noise, 2.0
                     # interleaved gradient noise; both change with P_SEED (one per frame)
P_SEED = 15          # integer seed for the start-jitter hash
P_BLOCK = 16         # empty-space-skipping block edge, voxels
P_HAS_PREV = 17      # 1.0 when prev_vp holds a previous camera
P_DEPTH_MODE = 18    # the point motion vectors reproject: 0 max alpha, 1 opacity threshold, 2 opacity-weighted mean
P_DEPTH_THRESHOLD = 19  # accumulated opacity mode 1 looks for (max alpha where it is never reached)
P_SLABS = 20         # depth slabs each ray also composites apart (0: none; the slabs array is then unused)
P_SIZE = 21

# out: float32[H, W, OUT_CHANNELS], one pass's feature buffers -----------------------------------
OUT_COLOR = 0        # 3: RGB composited over the background
OUT_ALPHA = 3        # 1: accumulated opacity
OUT_DEPTH = 4        # 1: quasi-depth in [0, 1] at the sample of maximum alpha (1 = background)
OUT_MAX_RGBA = 5     # 4: shaded RGB and alpha of the sample of maximum alpha (0 for background)
OUT_POSITION = 9     # 3: world position (mm) of that sample (focal-plane point for background)
OUT_MOTION = 12      # 2: motion vector (pixels) to the previous frame
OUT_MOTION_DEPTH = 14  # 1: quasi-depth of the point the motion vector reprojects (P_DEPTH_MODE; 1 = background)
OUT_CHANNELS = 15

# slabs: float32[K, H, W, SLAB_CHANNELS], the same pass cut into K depth slabs (P_SLABS > 0) -----------
SLAB_RGBA = 0        # 4: premultiplied RGB and alpha of the slab's samples alone, composited front to back
SLAB_MOTION = 4      # 2: motion vector (pixels) of the slab's opacity-weighted mean point; 0 where the slab is empty
SLAB_CHANNELS = 6
