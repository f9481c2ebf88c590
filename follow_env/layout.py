"""Index layout of the batched core's arrays (generated once, edited by hand since).

The numba kernels read every parameter and state variable from a few 2-D float/int arrays
with one row per lane; these module constants name the columns. Kept in one place so the
kernels, the environments and the renderer agree.
"""

# --- per-lane parameters: ``params[lane, P_*]`` (float64), filled from EnvConfig ---
P_WHEEL_R = 0
P_TRACK = 1
P_FOOT_L = 2
P_FOOT_W = 3
P_MOTOR_WMAX = 4
P_MOTOR_ALPHA = 5  # 1 - exp(-dt_in / tau): the motor lag over one 10 ms tick
P_FRIC_DUTY = 6
P_STALL_DUTY = 7
P_MAX_DUTY = 8
P_GAIN_R = 9
P_GAIN_L = 10
P_COUNTS_PER_REV = 11
P_DT_IN = 12
P_SPEED_Q = 13
P_SUBSTEPS = 14
P_KP = 15
P_KI = 16
P_KD = 17
P_TAU_D = 18
P_ANTI_WINDUP = 19
P_IMG_W = 20
P_IMG_H = 21
P_FX = 22
P_FY = 23
P_CX = 24
P_CY = 25
P_R00 = 26
P_R01 = 27
P_R02 = 28
P_R10 = 29
P_R11 = 30
P_R12 = 31
P_R20 = 32
P_R21 = 33
P_R22 = 34
P_TX = 35
P_TY = 36
P_TZ = 37
P_DEPTH_MIN = 38
P_DEPTH_MAX = 39
P_DEPTH_K = 40
P_DEPTH_UNIT = 41
P_INVALID_P = 42
P_LATENCY = 43
P_MISS_P = 44
P_BURST_START = 45
P_BURST_END = 46
P_JIT_C = 47
P_JIT_S = 48
P_MIN_VIS = 49
P_MIN_BOX_H = 50
P_HIST_LEN = 51
P_PERSON_H = 52
P_PERSON_W = 53
P_PERSON_D = 54
P_PERSON_ACC = 55
P_PERSON_DEC = 56
P_TARGET_D = 57
P_R_ALIVE = 58
P_R_DIST = 59
P_R_OFF = 60
P_R_ACC = 61
P_R_LOST = 62
P_R_COLL = 63
P_DT = 64
P_MAX_STEPS = 65
P_LOST_TIMEOUT = 66
P_CLEARANCE = 67
P_SETTLE = 68
P_WALL_R = 69
P_V_MAX = 70
P_W_MAX = 71
P_WHEEL_R_TRUE = 72  # the wheels' real radius (WHEEL_R is what the controller assumes)
P_TRACK_TRUE = 73  # the real track width (TRACK is what the controller assumes)
P_ENC_NOISE = 74  # std of extra encoder counts per tick
P_PUSH_P = 75  # chance per control step of a push
P_PUSH_V = 76  # push speed (m/s) for one control step
P_ASSOC = 77  # 0: first detection (reference), 1: tracker
P_TRK_IOU = 78  # tracker gate: least IoU with the predicted box
P_TRK_COAST = 79  # tracker: frames kept without a match
P_SOCIAL_R = 80  # people keep this far from each other (m)
P_SOCIAL_K = 81  # strength of the sideways social force (m/s^2)
P_TRK_APP_GATE = 82  # tracker: largest appearance difference of the same person
P_APP_NOISE = 83  # std of the appearance a detection carries
N_PARAMS = 84

# --- per-lane float state: ``fstate[lane, S_*]`` ---
S_X = 0
S_Y = 1
S_TH = 2
S_V = 3
S_W = 4
S_OMEGA_R = 5
S_OMEGA_L = 6
S_ANG_R = 7
S_ANG_L = 8
S_VMEAS_R = 9
S_VMEAS_L = 10
S_VTGT_R = 11
S_VTGT_L = 12
S_INT_R = 13
S_INT_L = 14
S_EPREV_R = 15
S_EPREV_L = 16
S_D_R = 17
S_D_L = 18
S_DUTY_R = 19
S_DUTY_L = 20
S_VROBOT_MEAS = 21
S_VROBOT_PREV = 22
S_ACCEL = 23
S_T = 24
S_LOST_T = 25
S_WALK_END_T = 26
S_OBS_D = 27
S_OBS_O = 28
S_TRUE_D = 29
S_TRUE_O = 30
S_IN_FRAME = 31
S_DETECTED = 32
S_BOX_X1 = 33
S_BOX_Y1 = 34
S_BOX_X2 = 35
S_BOX_Y2 = 36
S_RAW_DEPTH = 37
S_CLEAR_WALL = 38
S_CLEAR_PERSON = 39
S_REWARD = 40
S_TERM = 41
S_TRUNC = 42
S_TRK_CX = 43
S_TRK_CY = 44
S_TRK_W = 45
S_TRK_H = 46
S_TRK_VX = 47
S_TRK_VY = 48
S_TRK_LOST = 49
S_TRK_ON = 50
S_VIS_FRAC = 51
S_PUSH_VX = 52
S_PUSH_VY = 53
S_TRK_APP = 54  # the target's appearance as the tracker learnt it (-1: not yet)
HIST_MAX = 32  # longest distance-filter history (PerceptionConfig.filter_history)
S_HIST0 = 55
DL_MAX = 9  # delay-line slots: latency_frames <= 8
DL_FIELDS = 9  # detected, cu, cv, raw depth, box x1, y1, x2, y2, whose (person index)
S_DL0 = S_HIST0 + HIST_MAX
S_SCRATCH0 = S_DL0 + DL_MAX * DL_FIELDS  # per-lane scratch for the camera (8 corners x 3)
N_SCRATCH = 24 + 64  # 8 body corners x 3, then up to 64 occluder indices
N_FSTATE = S_SCRATCH0 + N_SCRATCH

# --- per-lane integer state: ``istate[lane, I_*]`` (int64) ---
I_STEP = 0
I_ENC_R = 1
I_ENC_L = 2
I_HIST_N = 3
I_HIST_HEAD = 4
I_DL_HEAD = 5
I_N_PEOPLE = 6
I_N_WALLS = 7
I_REASON = 8
I_DETECTED_ID = 9
PEOPLE_MAX = 16  # burst state slots (one per person)
I_BURST0 = 10
N_ISTATE = I_BURST0 + PEOPLE_MAX

# --- per-person state: ``pstate[lane, person, PS_*]`` (float64); person 0 is the target ---
PS_S = 0
PS_V = 1
PS_SEG = 2
PS_PAUSE = 3
PS_X = 4
PS_Y = 5
PS_TH = 6
PS_DONE = 7
PS_NPTS = 8
PS_LAT = 9
PS_LATV = 10
PS_FORCE = 11
PS_SLOW = 12
N_PSTATE = 13

# --- path waypoints: ``paths[lane, person, k, PW_*]`` (float64) ---
PW_X = 0
PW_Y = 1
PW_S = 2
PW_VMAX = 3
PW_PAUSE = 4
N_PW = 5

# --- walls and obstacles: ``walls[lane, k, W_*]`` (float64): a segment and its height ---
W_X1 = 0
W_Y1 = 1
W_X2 = 2
W_Y2 = 3
W_H = 4  # height (m): walls and pillars are tall, furniture low
WALL_FIELDS = 5

# --- episode end reasons (``istate[lane, I_REASON]``) ---
REASON_NONE = 0
REASON_COLLISION_WALL = 1
REASON_COLLISION_PERSON = 2
REASON_LOST = 3
REASON_WALK_OVER = 4
REASON_STEP_LIMIT = 5
REASON_COLLISION_BYSTANDER = 6
REASON_NAMES = (
    "",
    "collision_wall",
    "collision_person",
    "lost",
    "walk_over",
    "step_limit",
    "collision_bystander",
)
