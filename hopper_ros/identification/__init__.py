"""Parameter identification and validation of the predictors (chapter 4 of the thesis), plain
numpy/scipy on top of the model library (`hopper_ros.physics`) and the recordings
(`hopper_ros.recording.recordings`, which decodes a bag's messages). No ROS import.

- `strides`     apex-to-apex strides, phases, inputs from the kinematics (section 4.1)
- `cost`        E_p, E_v, E_t (4.1)-(4.3) of recorded strides and the cost C (4.4)
- `fit`         Nelder-Mead identification with the AAS, the corrected AAS or the exact model
- `lanesfit`    identification with library effects: the laws re-simulate the strides (physics.lanes),
                least squares, the folds' lanes calls batched (`hopper identify --effects`)
- `crossval`    k-fold cross-validation, Table 4.1 and Table 4.2
- `identifiability`  what apex-to-apex data can identify, structurally and in numbers
- `grf`         ground reaction forces from kinematics and force plate, virtual footfalls (4.4)
                (the simulated GRF experiments: `hopper_ros.harness.grf`)
- `pipeline`    recording -> strides -> cross-validation -> identifiability
- `settings`    config/identification.yaml
- `progress`    the progress bar (tqdm's, one line per step off a terminal)
"""
