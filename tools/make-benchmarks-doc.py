#!/usr/bin/env python3
"""Writes docs/benchmarks.md from the benchmarks' JSON files (out/bench/*.json, written by `make bench`).

usage: make-benchmarks-doc.py [--bench-dir out/bench] [--output docs/benchmarks.md]

For each benchmark the page gives what it measures, on which data, how each figure is computed and its target (the
texts below, in BENCHMARKS), then the figures of its JSON file as tables. A JSON file without a description gets a
generic section; a described benchmark whose file is missing gets a line saying it was not run. The date shown is
the file's modification time, unless the file holds a string "_measured_on"; a string "_note" is printed above the
figures. Other keys beginning with "_" are not figures.

Exit status: 0 written; 1 written, but a JSON file could not be read (the page says which); 2 bad argument.
Standard library only.
"""
import argparse
import datetime
import fnmatch
import glob
import json
import math
import os
import sys
import tempfile

# ---------------------------------------------------------------------------------------------------------------
# What each benchmark measures. Keyed by the JSON file's name, in the order of the page.
#   title, command, measures, data, method (list of paragraphs), targets (list), references (list, optional),
#   figures: [(pattern, meaning)]: the first fnmatch pattern matching a figure's dotted key (or, inside a table of
#            records, its column name) gives the meaning printed beside it;
#   omit: fnmatch patterns of dotted keys not shown (bulky per-item lists kept in the JSON file only);
#   groups: {top-level key: caption} for the tables of records.

BENCHMARKS = {
    'dive_synth.json': {
        'title': 'Dive simulator rendering speed',
        'command': 'devel/lib/exocet_mosaic/bench_dive_synth --output-dir out/bench',
        'measures': 'How many frames per second `dive_synth` renders on one thread, the seabed texture tiles '
                    'generated along the track included. Frames are rendered and dropped: the disk is not measured.',
        'data': 'A simulated out-and-back dive (60 m line at 0.5 m/s, 10 frames/s) with the sample dive\'s '
                'underwater effects: lamp cone 0.7, vignetting 0.4, attenuation [0.3, 0.1, 0.08] per metre, '
                'backscatter 0.15, read noise 2 DN, marine snow 15 particles per cubic metre. PAL (720x576) and HD '
                '(1920x1080) cameras, each over a flat seabed and over a seabed with relief (per-pixel ray casting).',
        'method': ['Wall-clock time of `DiveSynthesizer::run` over 150 PAL or 40 HD frames, one rendering thread.'],
        'targets': ['None: the figure tells how long `make bags` and the benchmarks\' dives take to render.'],
        'figures': [
            ('fps_pal', 'frames/s, 720x576, flat seabed'),
            ('fps_pal_relief', 'frames/s, 720x576, seabed with relief'),
            ('fps_hd', 'frames/s, 1920x1080, flat seabed'),
            ('fps_hd_relief', 'frames/s, 1920x1080, seabed with relief'),
            ('frames_pal', 'frames rendered per PAL run'),
            ('frames_hd', 'frames rendered per HD run'),
            ('threads', 'rendering threads'),
        ],
    },
    'mosaic_video.json': {
        'title': 'One command from a video to tiles (mosaic_video)',
        'command': 'devel/lib/exocet_mosaic/bench_mosaic_video --output-dir out/bench --shared-data ../shared/data',
        'measures': 'The `mosaic_video` tool end to end (its core, `VideoMosaicker`: registration, images-only '
                    'fusion, composer, GeoTIFF writer in one process) on a rendered video with the navigation '
                    'withheld, beside OpenCV\'s `cv::Stitcher` (SCANS); the real Sparus II video with and without '
                    'its navigation.',
        'data': '`src/exocet_mosaic/config/dives/bench_mosaic_video.yaml`: PAL at 10 frames/s, out and back along '
                'a 10 m line at 2.5 m over a wreck site (`seabed.objects: wreck`), eight checker targets; the tool '
                'gets the start point, the heading and the altitude only. Sparus: `../shared/data/sparus_auv`.',
        'method': [
            'Frames placed: frames with a fused pose composed into the mosaic, over the frames read.',
            'Landmark distances: the checker targets found in the tiles (template match within 0.6 m of the '
            'surveyed place, then the saddle to a fraction of a pixel; a checker found twice counts once, and it '
            'is the surveyed spot nearest to it once the tile\'s common offset, the median over its checkers, is '
            'taken off); the distance between every pair of sightings of two different spots at least 0.5 m '
            'apart against the surveyed distance, in per cent (median, p95; `_same_tile`: both in one tile).',
            '`cv::Stitcher` SCANS on every 10th frame in a child process abandoned after the time limit '
            '(`stitcher_seconds` null when it did not finish).',
        ],
        'targets': [
            'Frames placed at least 99 %; landmark distances within 1 %; at least 100 frames/s end to end (PAL).',
        ],
        'figures': [
            ('frames_placed_fraction', 'fraction of the frames placed'),
            ('landmark_distance_err_pct', 'median error of the distances between landmark sightings (%)'),
            ('fps_pal', 'frames per second end to end (PAL)'),
            ('seconds', 'wall time of the tool on the rendered video (s)'),
            ('stitcher_seconds', 'cv::Stitcher SCANS wall time (s), null if unfinished'),
            ('sparus_frames_placed', 'Sparus II: frames placed without navigation'),
        ],
    },
    'registration.json': {
        'title': 'Frame-to-frame registration',
        'command': 'devel/lib/exocet_mosaic/bench_registration --output-dir out/bench --shared-data ../shared/data '
                   '[--only accuracy,peers,speed] [--methods klt,rmr,...]; '
                   'devel/lib/exocet_mosaic/bench_registration_node (the node as a process)',
        'measures': 'Accuracy, robustness, covariance consistency and speed of the registration methods (KLT, RMR, '
                    'auto) of `exocet_mosaic`, beside two OpenCV pipelines; agreement with a SIFT reference on real '
                    'seabed images; memory and throughput of `registration_node` as a process.',
        'data': 'Simulated: `src/exocet_mosaic/config/dives/bench_registration.yaml`, 2000 PAL frames (720x576, 25 frames/s, 80 s) '
                'over a flat seabed at 2.5 m altitude (altitude varying by 0.3 m), an out-and-back line with a '
                'U-turn, roll and pitch oscillating by 2 degrees, lamp cone, vignetting, colour attenuation, '
                'backscatter, read and shot noise, marine snow (20 particles per cubic metre), a turbid stretch '
                '(15-30 s, turbidity 3) and a dark one (45-55 s, light gain 0.3). The seabed is flat, so the true '
                'motion between two frames is exactly the seabed plane\'s homography, computed from the simulator\'s '
                'camera poses. The HD speed uses the first 12 s of the same dive rendered at 1920x1080. '
                'Real: the 22 frames (384x288) of the Sparus II AUV sample (`../shared/data/sparus_auv`), undistorted '
                'with the dataset\'s intrinsics. The node figures replay `bags/sample_out_and_back.bag` (JPEG, PAL). '
                'Strong relief (`wreck_*`): `src/exocet_mosaic/config/dives/wreck.yaml`, 1500 PAL frames (60 s) out '
                'and back at 1.5-3 m over piles of amphorae and blocks 0.2-0.6 m tall with sides up to 72 degrees '
                '(`seabed.objects: wreck`) on a flat seabed, a lamp offset to starboard with a narrow cone.',
        'method': [
            'Corner-transfer error: for each image pair, the largest distance (px) between where the estimated and '
            'the true motion send the four image corners. Median and p95 are over the pairs the method did not '
            'report as failed. A failure is a pair the method reports as failed; a gross failure is a pair not '
            'reported as failed whose error exceeds 2 px. Rates are fractions of the pairs scored (`dive_pairs`; '
            '0.005 = 0.5 %).',
            'Each method runs over the whole sequence through registration_node\'s own front-end '
            '(`SequenceRegistrar`: the previous motion scaled to the frame interval as the starting guess, the '
            'restart policy, the fallback), with illumination normalisation. Keys without a suffix (`klt_*`, '
            '`rmr_*`, `auto_*`) use the homography model; `*_similarity` and `*_affine` the other models. The dark '
            'and turbid medians are the same run scored on those stretches only.',
            'NEES ratio: median over the pairs of the corner NEES (errors weighed by the reported covariance) '
            'divided by its expectation for a right covariance; 1 is consistent, above 1 the covariance is too '
            'small.',
            'Peers: OpenCV `findTransformECC` (affine, 3-level pyramid) and ORB (1000 features) + '
            '`estimateAffinePartial2D` (RANSAC), on every 5th pair (every 50th for ECC\'s HD speed).',
            'Speed: the same front-end on 300 frames (12 s) of the dive, repeated for at least 2-3 s of wall time, one '
            'thread (`cv::setNumThreads(1)`), illumination normalisation included; `*_fps_*` is wall-clock, '
            '`*_fps_*_cpu` per second of the thread\'s CPU time. `klt_fps_pal` and `rmr_fps_pal` use the '
            'similarity model, `*_homography_fps_*` the homography. On a shared machine the wall-clock rate varies '
            'with the load; the CPU rate much less.',
            'Wreck: KLT and RMR (homography) over every pair (stride 1) and over every 4th frame (stride 4, '
            '`*_s4`), against the dominant plane\'s homography (the flat seabed under the objects): the parallax '
            'of the objects is what a method must not report as the seabed\'s motion.',
            'Sparus: every consecutive pair registered (homography) and compared, by the same corner distance, with '
            'a SIFT + RANSAC (MAGSAC++) homography of the same pair.',
            'Camera presets (`preset_*`, issue 23): the first 250 frames (10 s) of the dive rendered by the `pal`, '
            '`hd` and `uhd` camera presets (720x576, 1920x1080, 3840x2160), each registered by the front-end with its '
            'registration preset (`config/registration/<camera>_survey.yaml`, read by `video::loadRegistrationPreset` '
            'as registration_node reads it). Errors in the camera\'s pixels and in pixels of the HD image (x 1920 / '
            'width: the same ground distance for every camera); gross failures above 2 HD px; CPU of the thread per '
            'frame.',
            'Node: `registration_node` with `src/exocet_mosaic/config/registration/pal_survey.yaml` on a private ROS master; the '
            'bag\'s compressed images played at `node_replay_rate` times real time; peak resident memory (VmHWM) '
            'and motions published per second, JPEG decoding included.',
        ],
        'targets': [
            'KLT at least 400 frames/s on PAL and 150 on HD; RMR at least 100 and 30 (one thread).',
            'UHD (issue 23): corner error in HD pixels at most the HD preset\'s.',
            'Wreck: KLT and RMR failures at most 0.5 % at strides 1 and 4; KLT median at most 0.3 px, p95 at most '
            '1 px, NEES ratio between 0.5 and 2 (stride 1).',
            'Median error at most 0.1 px, p95 at most 0.5 px, gross failures at most 0.5 % (homography model).',
            'The similarity and affine models cannot meet them on this dive: a rolling and pitching camera sees '
            'perspective, which only the homography holds. The mosaic chain (`src/exocet_mosaic/launch/mosaic_chain.launch`) '
            'registers with the homography for that reason.',
        ],
        'figures': [
            ('preset_*_hd_px', 'camera preset: corner error in pixels of the HD image'),
            ('preset_*_cpu_ms_per_frame', 'camera preset: CPU per frame, one thread (ms)'),
            ('preset_*_px', 'camera preset: corner error in the camera\'s pixels'),
            ('preset_*_rate', 'camera preset: failure rates'),
            ('*_dark_median_px', 'median corner error (px) in the dark stretch'),
            ('wreck_*_failure_rate_s1', 'wreck: fraction of consecutive pairs reported as failed'),
            ('wreck_*_failure_rate_s4', 'wreck: fraction of pairs 4 frames apart reported as failed'),
            ('wreck_*_px_s4', 'wreck, pairs 4 frames apart: corner error against the dominant plane (px)'),
            ('wreck_*_fps', 'wreck: frames registered per second in the accuracy run (wall clock)'),
            ('wreck_pairs', 'wreck: consecutive pairs scored'),
            ('*_turbid_median_px', 'median corner error (px) in the turbid stretch'),
            ('sparus_*_max_corner_px', 'Sparus: largest corner difference to SIFT + RANSAC (px)'),
            ('sparus_*_median_corner_px', 'Sparus: median corner difference to SIFT + RANSAC (px)'),
            ('sparus_*_failures', 'Sparus: pairs reported as failed'),
            ('sparus_max_corner_px', 'Sparus: largest corner difference of KLT and RMR (px)'),
            ('*_median_px', 'median corner-transfer error (px)'),
            ('*_p95_px', '95th percentile of the corner-transfer error (px)'),
            ('*_gross_failure_rate', 'fraction of pairs with an unreported error > 2 px'),
            ('*_failure_rate', 'fraction of pairs reported as failed'),
            ('*_nees_ratio', 'covariance consistency (1 = right, > 1 = too small)'),
            ('*_fps_pal_cpu', 'frames per CPU second, 720x576, one thread'),
            ('*_fps_hd_cpu', 'frames per CPU second, 1920x1080, one thread'),
            ('node_fps_pal', 'registration_node: motions published per second (PAL, JPEG)'),
            ('node_peak_rss_mb', 'registration_node: peak resident memory (MB)'),
            ('node_replay_rate', 'registration_node run: replay speed (x real time)'),
            ('*_fps_pal', 'frames/s wall-clock, 720x576, one thread'),
            ('*_fps_hd', 'frames/s wall-clock, 1920x1080, one thread'),
            ('dive_pairs', 'image pairs scored'),
        ],
    },
    'fusion.json': {
        'title': 'Navigation fusion',
        'command': 'devel/lib/exocet_mosaic/bench_fusion --output-dir out/bench [--monte-carlo RUNS] '
                   '[--filter NAME=VALUE]... [--monte-carlo-set navigation.KEY=VALUE]... [--no-cross-pass]',
        'measures': 'Position accuracy and consistency of the navigation filter (image motion, dead reckoning, USBL) '
                    'and of its Rauch-Tung-Striebel smoother, against each source alone: the out-and-back '
                    'experiment of the 2D3 report\'s figure 5.',
        'data': '`src/exocet_mosaic/config/dives/bench_fusion.yaml`: a 50 m line flown out and back at 0.4 m/s over a flat seabed, '
                'PAL camera at 5 frames/s, 2.5 m altitude (varying by 0.15 m), roll and pitch oscillating by 1 and '
                '1.5 degrees; USBL fixes of 0.5 m (1-sigma) at 1 Hz arriving 1.5 s late, 3 % outliers (10 times the '
                'noise) and a 40 s dropout on the way back (180-220 s); dead reckoning from gyro and DVL with the '
                'simulator\'s default drift; heading alignment error 2 mrad at launch. Ground truth: the simulator\'s '
                'camera centre at every frame.',
        'method': [
            'The simulator runs in-process. Consecutive frames are registered by registration_node\'s own '
            'front-end (`SequenceRegistrar`: homography, method auto), and every sensor\'s records are fed, in '
            'arrival order, to fusion_node\'s own front-end (`FusionFrontEnd`: attitude and altimeter histories, '
            'roll, pitch and range fitted over +-1 s at each image, metric conversion with the camera, lever arms) '
            'and its filter; the RTS smoother runs over the whole dive. Every track is scored against the true '
            'camera centre at the image stamps.',
            'The filter is configured from the simulated sensors\' specifications (gyro noise and bias, DVL noise and '
            'scale error), as an operator would from datasheets (`filterConfigForSensors`). The image step noise '
            'along and across each step\'s motion is calibrated from the registration\'s error against the '
            'simulator\'s truth, as one calibrates a sensor (`image_step_noise_calibrated_*`).',
            'RMSE: root mean square horizontal position error (m). "Better single source" is the smallest RMSE of '
            'image motion alone, dead reckoning alone and USBL alone; `filtered_over_better_single_source` is the '
            'filtered RMSE (all sources) divided by it, in the rendered dive and in each Monte Carlo run.',
            'Return misalignment: for each image of the return pass and the nearest image of the outbound pass, the '
            'error of their estimated relative position, in ground sample distances (GSD, the pixel size on the '
            'seabed); median and p95 over those pairs. Cross-pass constraints: SIFT matches between the passes '
            'added to the smoothed track in a Ceres batch adjustment.',
            'Consistency (NEES, normalised estimation error squared, 2 degrees of freedom): Monte Carlo over the '
            'navigation sensors (`nees_monte_carlo_runs` runs re-drawing gyro, DVL, altimeter, attitude, heading '
            'alignment and USBL noise and the focal length, along the same images); at each epoch the NEES averaged '
            'over the runs is compared with the 95 % chi-square bounds for that many runs '
            '(`nees_monte_carlo_bounds_low/high`). Per axis: along and across the track, 1 degree of freedom each. '
            '`monte_carlo_common_error_fraction`: squared mean error over mean squared error (1 / runs for '
            'independent runs). The single rendered dive\'s NEES (`nees_mean`, bounds [0.0506, 7.38]) is one '
            'realisation with strongly correlated epochs: the Monte Carlo is the test.',
        ],
        'targets': [
            'Filtered / better single source at most 0.5.',
            'Return-pass misalignment (p95, `return_misalignment_gsd`) at most 3 GSD.',
            'At least 95 % of the epochs within the Monte Carlo NEES bounds.',
        ],
        'figures': [
            ('rmse_image_only_m', 'image motion alone from the true start: RMSE (m)'),
            ('rmse_nav_only_m', 'dead reckoning alone: RMSE (m)'),
            ('rmse_usbl_only_m', 'USBL fixes alone, at their stamps: RMSE (m)'),
            ('rmse_usbl_only_inliers_m', 'USBL fixes without the outliers (> 4 sigma): RMSE (m)'),
            ('rmse_nav_filter_m', 'filter, dead reckoning + USBL: RMSE (m)'),
            ('rmse_nav_smoothed_m', 'RTS smoother, dead reckoning + USBL: RMSE (m)'),
            ('rmse_filtered_m', 'filter, all sources: RMSE (m)'),
            ('rmse_filtered_live_m', 'filter, all sources, as published live (before late fixes): RMSE (m)'),
            ('rmse_smoothed_m', 'RTS smoother, all sources: RMSE (m)'),
            ('rmse_cross_pass_m', 'RTS + cross-pass constraints: RMSE (m)'),
            ('filtered_over_better_single_source', 'filtered RMSE / better single source (target <= 0.5)'),
            ('return_misalignment_gsd', 'return-pass misalignment p95 of the best track (GSD; target <= 3)'),
            ('return_misalignment_gsd_*_median', 'return-pass misalignment, median (GSD)'),
            ('return_misalignment_gsd_*_p95', 'return-pass misalignment, p95 (GSD)'),
            ('return_pairs', 'return / outbound image pairs compared'),
            ('nees_in_bounds_fraction', 'Monte Carlo: fraction of epochs within the 95 % NEES bounds (target >= 0.95)'),
            ('nees_monte_carlo_runs', 'Monte Carlo runs'),
            ('nees_monte_carlo_mean', 'Monte Carlo NEES, mean over the epochs (2 expected)'),
            ('nees_monte_carlo_along_track_mean', 'Monte Carlo NEES along the track, mean (1 expected)'),
            ('nees_monte_carlo_cross_track_mean', 'Monte Carlo NEES across the track, mean (1 expected)'),
            ('nees_monte_carlo_bounds_*', '95 % bounds of the run-averaged NEES'),
            ('nees_monte_carlo_below_fraction', 'fraction of epochs below the bounds (covariance too large)'),
            ('nees_monte_carlo_above_fraction', 'fraction of epochs above the bounds (covariance too small)'),
            ('monte_carlo_common_error_fraction', 'error common to the runs (1 / runs if independent)'),
            ('monte_carlo_rmse_filtered_mean_m', 'Monte Carlo: filtered RMSE, mean (m)'),
            ('monte_carlo_rmse_nav_only_mean_m', 'Monte Carlo: dead reckoning RMSE, mean (m)'),
            ('monte_carlo_filtered_over_better_single_mean', 'Monte Carlo: filtered / better single source, mean'),
            ('monte_carlo_filtered_over_better_single_p90', 'Monte Carlo: filtered / better single source, p90'),
            ('monte_carlo_seconds', 'Monte Carlo wall time (s)'),
            ('nees_single_dive_in_bounds_fraction', 'rendered dive: fraction of epochs with NEES in [0.0506, 7.38]'),
            ('nees_mean', 'rendered dive: mean NEES of the filter (2 expected)'),
            ('nees_smoothed_mean', 'rendered dive: mean NEES of the smoother'),
            ('nees_below_fraction', 'rendered dive: fraction of epochs below 0.0506'),
            ('nees_above_fraction', 'rendered dive: fraction of epochs above 7.38'),
            ('image_step_noise_calibrated_along_m', 'image step noise along the motion, calibrated (m)'),
            ('image_step_noise_calibrated_across_m', 'image step noise across the motion, calibrated (m)'),
            ('metric_step_rmse_m', 'registration steps in metres against the truth: RMS error (m)'),
            ('true_heading_error_end_rad', 'heading error of the IMU at the end, true (rad)'),
            ('estimated_heading_error_end_rad', 'heading error at the end, estimated by the filter (rad)'),
            ('estimated_heading_error_end_sigma_rad', '1-sigma of that estimate (rad)'),
            ('usbl_fixes', 'USBL fixes'),
            ('usbl_outliers', 'USBL outliers (> 4 sigma)'),
            ('gated_fixes', 'fixes rejected by the gate (final)'),
            ('gated_fixes_at_arrival', 'fixes rejected by the gate on arrival'),
            ('recoveries', 'filter recoveries after consecutive rejections'),
            ('filter_events', 'filter events processed'),
            ('filter_updates_per_s', 'filter events per second of CPU'),
            ('filter_rewinds', 're-processings for late fixes'),
            ('frames', 'images'),
            ('path_length_m', 'camera path length (m)'),
            ('mean_gsd_m', 'mean ground sample distance (m)'),
            ('registration_failures', 'image pairs whose registration failed'),
            ('registration_pairs_per_s', 'registration speed in the benchmark (pairs/s)'),
            ('cross_pass_constraint_error_median_m', 'cross-pass constraints: median error (m)'),
            ('cross_pass_constraints', 'cross-pass constraints used'),
            ('cross_pass_seconds', 'cross-pass adjustment wall time (s)'),
            ('rts_seconds', 'RTS smoother wall time (s)'),
            ('bench_seconds', 'benchmark wall time (s)'),
        ],
    },
    'selfcal.json': {
        'title': 'Camera self-calibration',
        'command': 'devel/lib/exocet_mosaic/bench_selfcal --output-dir out/bench [--runs N]',
        'measures': 'Accuracy of the intrinsics (focal lengths alpha_u, alpha_v in pixels, principal point u0, v0) '
                    'estimated without a pattern by `self_calibrate` (Mendonca-Cipolla cost over fundamental '
                    'matrices; Triggs\' planar method on a flat seabed), and of the project\'s fundamental-matrix '
                    'estimator against OpenCV\'s.',
        'data': 'Synthetic sequences reproducing the 2D3 report\'s Table 1 experiment: 8 key frames over a seabed '
                'with +-0.5 m relief seen from 3 m, rotation of 40 degrees about the optical axis plus 8 degrees of '
                'roll and pitch, 0.5 px image noise (`--runs`, default 50, seeds 1000 onwards). For the fundamental '
                'matrix, 10 such sequences with 10 % of the observations wrong (about 19 % of the matches). For the '
                'planar method, 20 flat sequences. End to end: a dive rendered by the simulator over relief, and '
                'the same dive over a flat seabed. Strong relief (`wreck_*`): the first 900 frames (36 s, 90 key '
                'frames) of `src/exocet_mosaic/config/dives/wreck.yaml` (out and back over amphorae and blocks '
                '0.2-0.6 m tall at 1.5-3 m, a U-turn, roll and pitch +-3 degrees, lamp offset to starboard); '
                '`wreck_tilt8_*`: the same with +-8 degrees of roll and pitch (`--wreck-frames N`).',
        'method': [
            'Errors are |estimate - truth| / truth in % for each intrinsic; mean over the runs, and the largest. '
            '`sigma_*_mean_pct` is the mean 1-sigma the calibration reports; `monte_carlo_within_1_sigma_pct` the '
            'share of errors within it.',
            'Fundamental matrix: the project\'s normalised 8-point inside MSAC against `cv::findFundamentalMat` '
            '(FM_RANSAC), same 1 px threshold: RMS Sampson distance of the exact (noise-free) matches and of the '
            'noisy inliers, distance to the true F, and time per pair.',
            'A flat seabed must be refused by the default calibration (GRIC prefers a homography): '
            '`flat_refused_fraction`, `e2e_flat_refused`.',
            'The reported 1-sigma is the larger of the calibrator\'s residual-based one and a key-frame bootstrap '
            '(200 replicates: key frames drawn with replacement, each pair weighed by its key frames\' '
            'multiplicities): pairs sharing a key frame share its tracks\' errors.',
            'Wreck dives: KLT tracks (a key frame every 10 frames), calibrated with the acceptance switched off so '
            'that the estimate is always measured; `*_z_*` is (estimate - truth) / reported 1-sigma, '
            '`*_z_residual_*` the same with the residual-based 1-sigma; `*_refused` whether the default acceptance '
            '(every 1-sigma within 10 % of its value) refuses it. Two controls locate the error: the same cost on '
            'the exact fundamental matrices of the pairs used (`*_exact_f_err_*_pct`: the motion alone), and the '
            'RMS Sampson distance of the inlier tracks to the exact epipolar geometry (the tracking).',
        ],
        'targets': ['Mean errors below the 2D3 report\'s Table 1 (`report_err_*_pct`).'],
        'references': ['2D3 report, Table 1 (mean |error| %): alpha_u 2.06, alpha_v 2.06, u0 1.65, v0 1.19.'],
        'figures': [
            ('err_*_max_pct', 'largest |error| over the runs (%)'),
            ('err_*_pct', 'mean |error| over the runs (%)'),
            ('sigma_*_mean_pct', 'mean reported 1-sigma (%)'),
            ('report_err_*_pct', 'the 2D3 report\'s Table 1 (%)'),
            ('monte_carlo_runs', 'Monte Carlo runs'),
            ('monte_carlo_failures', 'runs where the calibration failed'),
            ('monte_carlo_within_1_sigma_pct', 'errors within the reported 1-sigma (%)'),
            ('monte_carlo_s_per_run', 'time per calibration (s)'),
            ('f_ours_sampson_exact_px', 'ours: RMS Sampson distance of the exact matches (px)'),
            ('f_opencv_sampson_exact_px', 'OpenCV: RMS Sampson distance of the exact matches (px)'),
            ('f_ours_sampson_noisy_px', 'ours: RMS Sampson distance of the noisy inliers (px)'),
            ('f_opencv_sampson_noisy_px', 'OpenCV: RMS Sampson distance of the noisy inliers (px)'),
            ('f_ours_distance_to_true', 'ours: distance to the true F'),
            ('f_opencv_distance_to_true', 'OpenCV: distance to the true F'),
            ('f_ours_ms', 'ours: time per pair (ms)'),
            ('f_opencv_ms', 'OpenCV: time per pair (ms)'),
            ('planar_err_*_pct', 'planar (Triggs) on flat sequences: mean |error| (%)'),
            ('flat_refused_fraction', 'flat sequences refused by the default calibration'),
            ('e2e_flat_refused', 'rendered flat dive refused by the default calibration (1 = yes)'),
            ('e2e_flat_planar_err_*_pct', 'rendered flat dive, planar method: |error| (%)'),
            ('e2e_err_*_pct', 'rendered dive over relief: |error| (%)'),
            ('wreck*_err_*_pct', 'wreck: |error| (%)'),
            ('wreck*_exact_f_err_*_pct', 'wreck, exact fundamental matrices: |error| (%)'),
            ('wreck*_sigma_*_px', 'wreck: reported 1-sigma (px)'),
            ('wreck*_z_residual_*', 'wreck: error / residual-based 1-sigma'),
            ('wreck*_z_*', 'wreck: error / reported 1-sigma'),
            ('wreck*_refused', 'wreck: refused by the default acceptance (1 = yes)'),
            ('wreck*_inlier_sampson_to_true_rms_px', 'wreck: inlier tracks, RMS Sampson distance to the exact F (px)'),
            ('wreck*_inliers_beyond_1px_pct', 'wreck: inlier tracks beyond 1 px of the exact F (%)'),
            ('wreck*_pairs_used', 'wreck: key-frame pairs used'),
            ('wreck*_frames', 'wreck: frames calibrated from'),
        ],
    },
    'pose_graph.json': {
        'title': 'Pose graph of the key frames (scale)',
        'command': 'devel/lib/exocet_mosaic/bench_pose_graph --output-dir out/bench [--keyframes N]',
        'measures': 'The cost of the 2-D pose graph (`exocet_mosaic_graph`: odometry, dead-reckoning relative '
                    'positions, interpolated USBL fixes with a Cauchy loss, the dead reckoning\'s start as a prior, '
                    'headings, switchable loop closures, Ceres) on a one-hour survey: the CPU time of '
                    're-solving after one new loop (the window it affects) and of a full re-solve, memory, and '
                    'whether planted false loops are rejected.',
        'data': 'Simulated factors (no images): 9000 key frames on a 30-line lawnmower, odometry with 1 % of the '
                'distance and 0.2 degrees per key frame, 3600 USBL fixes (0.5 m 1-sigma, 1 % outliers 5-15 m off), '
                'a heading per key frame (1 degree), the dead reckoning between consecutive key frames as the fusion '
                'models it (2 cm 1-sigma per 0.2 m step) and its start (1 cm), 500 true loops between adjacent lines '
                'and 20 false ones (1 m off, 2 cm 1-sigma).',
        'method': [
            '`resolve_cpu_s`: CPU seconds of the solve after one new loop is added to the solved graph, with the '
            'default window policy (the key frames touched by new factors and the loop\'s span, widened); '
            '`full_resolve_cpu_s` the same with every key frame free; `full_solve_cpu_s` the first solve of the '
            'whole graph, the loops\' consistency tests included. `growth`: the same at 1000, 3000 and 9000 key '
            'frames.',
            '`peak_rss_mb`: the process\'s VmHWM. Errors: RMS of the key frames\' positions against the truth.',
            'The graph\'s own 1-sigma: `marginals_cpu_s`, the key frames\' position marginals as the fusion computes '
            'them (PoseGraph::positionCovariances with BackgroundPoseGraph\'s cap: 500 computed, the others '
            'interpolated), after the full re-solve, per size in `growth`; `marginals_every_key_frame_cpu_s` all '
            'of them computed; `marginals_interpolation_error_max` the largest relative error of an interpolated '
            'radial 1-sigma; against the truth, the Mahalanobis distance sqrt(e^T C^-1 e) of each key frame\'s '
            'error (median 1.18 and 0.39 of them within 1 for errors drawn from the graph\'s own covariance).',
        ],
        'targets': ['Re-solve after a new loop at most 1 s of CPU; memory under 500 MB; no false loop accepted '
                    '(issue 20).'],
        'figures': [
            ('keyframes', 'key frames in the graph'),
            ('loops', 'loop closures (true and false)'),
            ('resolve_cpu_s', 're-solve after one new loop, windowed (CPU s)'),
            ('full_resolve_cpu_s', 're-solve after one new loop, all key frames free (CPU s)'),
            ('full_solve_cpu_s', 'first full solve, loop tests included (CPU s)'),
            ('peak_rss_mb', 'peak resident memory (MB)'),
            ('false_loops_planted', 'false loops planted'),
            ('false_loops_accepted', 'false loops accepted'),
            ('true_loops*', 'true loops (planted, accepted)'),
            ('rms_error_*_m', 'RMS position error against the truth (m)'),
            ('marginals_cpu_s', 'the key frames\' position marginals as the fusion computes them (CPU s)'),
            ('marginals_every_key_frame_cpu_s', 'every key frame\'s marginals computed (CPU s)'),
            ('marginals_key_frames_computed', 'key frames whose marginals are computed, the others interpolated'),
            ('marginals_interpolation_error_max', 'largest relative error of an interpolated 1-sigma'),
            ('marginals_sigma_radial_median_m', 'the graph\'s radial 1-sigma, median over key frames (m)'),
            ('marginals_within_1sigma_fraction', 'key frames whose error is within their 1-sigma ellipse (0.39 if '
                                                 'calibrated)'),
            ('marginals_mahalanobis_median', 'Mahalanobis distance of the key frames\' errors, median (1.18 if '
                                             'calibrated)'),
        ],
    },
    'tiles.json': {
        'title': 'Live mosaicking chain and GeoTIFF tiles',
        'command': 'devel/lib/exocet_mosaic/bench_tiles --output-dir out/bench [--dives pal,hd,grid,uhd] '
                   '[--graph-modes off,on] [--pal-rate R] [--hd-rate R] [--grid-rate R] [--uhd-rate R] [--attempts N]',
        'measures': 'Throughput, latency and memory of the live chain (registration_node -> fusion_node -> '
                    'tile_writer_node, as `src/exocet_mosaic/launch/replay.launch` runs it) on a replayed dive, and the geometric '
                    'quality and the colour agreement of the GeoTIFF tiles it writes, before and after `adjust_tiles`; '
                    'each dive replayed without and with the fusion\'s pose graph (`pose_graph:=true`).',
        'data': 'Four simulated dives with surveyed checker targets (0.3 m), JPEG images, USBL 0.5 m at 1 Hz '
                'arriving 1.5 s late. PAL: `src/exocet_mosaic/config/dives/bench_tiles_pal.yaml`, about 67 s at 25 frames/s, a '
                '3-line lawnmower (8 m lines 1.6 m apart, so that tiles of one line overlap tiles of the next), 2.5 m '
                'altitude, ten targets; presets `pal_survey`. HD: `src/exocet_mosaic/config/dives/bench_tiles_hd.yaml`, about 33 s of '
                '1920x1080 at 25 frames/s, a 3 m line out and back, six targets; presets `hd_survey`. Grid: '
                '`src/exocet_mosaic/config/dives/bench_tiles_grid.yaml`, about 91 s of PAL at 25 frames/s, three 3.2 m '
                'lines 1.6 m apart then three lines across them (waypoints, turns in place), ten targets; presets '
                '`pal_survey`. UHD: `src/exocet_mosaic/config/dives/bench_tiles_uhd.yaml`, the HD dive\'s line filmed '
                'by a 3840x2160 camera at 25 frames/s (811 frames, JPEG quality 90), six targets; presets `uhd_survey`.',
        'method': [
            'The dive is replayed with `rosbag play` at the goal\'s rate (8x real time for PAL, 2x for HD, 1x for UHD) on a '
            'private ROS master; after frames are dropped the rate is halved and the replay tried again (at most '
            '`--attempts` times). Throughput: frames over the time from the first to the last motion and pose '
            'through registration and fusion; the fusion\'s end-of-input flush (it holds the last 0.3 s of the bag '
            'until its inputs have been silent for 0.5 s) is left out and reported as `chain_end_of_input_flush_s`. '
            'A frame is dropped when its motion, its fused pose or its arrival at the tile writer is missing. Lag: '
            'arrival time minus where the replay clock puts the image. Memory: peak resident set (VmHWM) of each '
            'node (`<dive>_peak_rss_mb_max`: the largest). CPU: each node\'s user + system time over the replay, '
            'its start-up included, per frame of the bag (`<dive>_cpu_ms_per_frame`).',
            'Landmarks: each surveyed target inside a tile is found by template matching and a sub-pixel saddle '
            'search, and compared with its surveyed UTM position (m). The bound is max(2 GSD, the fused position '
            '1-sigma).',
            'Tile misalignment: the shift between two overlapping tiles on their common grid, by masked, windowed '
            'phase correlation of patches (px). Consecutive tiles share images; other overlapping pairs are return '
            'passes and crossings, whose misalignment is the live navigation\'s error between passes; '
            '`overlap_misalignment_max_px` (top level `<dive>_live_overlap_max_px`) is the largest over every pair. '
            '`adjusted_*`: the same measurements on the output of `adjust_tiles` applied to the tiles of the run '
            'without the graph (`adjusted_*_with_graph`: to those of the run with it).',
            'Colour agreement: each overlapping pair aligned by its measured shift (rounded to whole pixels), both '
            'data masks eroded by 3 px, luma = OpenCV BGR to GRAY (8-bit). Level step: |mean luma of one tile - '
            'mean luma of the other| on their common pixels, the largest over the pairs; |A-B| median: the median '
            'absolute luma difference pooled over the common pixels of every pair (grey levels). The live tiles '
            'carry a gain per image solved over the overlaps of the dive\'s images (`compose::ImageGains`, '
            '`~image_gain_compensation`); `recomposed_*`: `recompose_tiles` on the records of the run with the '
            'graph, with the same model solved again at the final placements, beside the same drawing with one gain '
            'per tile (`recomposed_tile_gains_*`, `compose::JointTileGains`) and with OpenCV\'s stitcher\'s '
            'per-image, per-channel compensator (`recomposed_opencv_gains_*`, `cv::detail::ChannelsCompensator` on the '
            'lighting-corrected images warped at 4 GSD).',
            'Recomposition: `recompose_tiles` draws each image at the graph\'s final corrections, then moves each '
            'by a small similarity that brings it into agreement with the images it overlaps '
            '(`tiles::adjustImages`: tie points by phase correlation of 48 px patches of each pair drawn on their '
            'common ground, RANSAC, robust sparse least squares, two passes); `recomposed_graph_only_*`: the same '
            'drawing without that adjustment.',
            'Graph modes: each dive is replayed with `pose_graph:=false` then `pose_graph:=true` (`--graph-modes`); '
            'the figures of the run with the graph have the plain names, those of the run without it the suffix '
            '`_without_graph`. `rate_no_drop` (top level `<dive>_rate_no_drop`): the replay rate at which no frame '
            'was dropped, null when every attempt dropped frames. PAL and HD are also replayed once at the archive rate '
            '(16x, 4x; `probe_*`): when no frame drops there, that rate is the `rate_no_drop`; the other figures are '
            'those of the first rate (8x, 2x), the probe\'s tiles measured beside them (`*_probe_live_*`).',
        ],
        'targets': [
            'PAL replayed at 8x real time (200 frames/s) and HD at 2x (50 frames/s) with no frame dropped.',
            'UHD (issue 23): live at 1x with no frame dropped, peak resident memory of every node under 500 MB; PAL '
            'at 16x and HD at 4x.',
            'Landmark errors within the bound max(2 GSD, fused 1-sigma).',
            'After `adjust_tiles`, overlapping tiles misaligned by at most 2 px.',
            'With the graph (issue 20): every pair of live tiles within 2 px; recomposed, every pair within 1 px and '
            'landmark p95 at most half of the live figure without the graph; mean-level step between overlapping '
            'live tiles at most 3 grey, |A-B| median at most 4.',
        ],
        'omit': ['dives.*.attempts*', 'dives.*.landmark_observations*', 'dives.*.pairs', 'dives.*.pairs_without_graph',
                 'dives.*.tile_list*', 'dives.*.tile_write_ms', 'dives.*.tile_write_ms_without_graph',
                 'dives.*.tile_write_ms.*', 'dives.*.tile_write_ms_without_graph.*', 'dives.*.registration_lag_s*',
                 'dives.*.fusion_lag_s*', 'dives.*.tiles_dir*', 'dives.*.landmarks_ambiguous*',
                 'dives.*.overlap_colour_per_pair*'],
        'groups': {'dives': 'Per dive'},
        'figures': [
            ('chain_fps*without_drops', 'no frame dropped at that rate'),
            ('chain_fps*', 'chain throughput (frames/s)'),
            ('chain_rate*', 'replay rate (x real time)'),
            ('rate', 'replay rate (x real time)'),
            ('frames', 'frames in the bag'),
            ('frames_dropped*', 'frames dropped'),
            ('frames_before_first_pose', 'frames before the fusion\'s first pose'),
            ('chain_end_of_input_flush_s', 'fusion end-of-input flush after the last frame (s)'),
            ('registration_lag_max_s', 'largest lag of the registration behind the replay (s)'),
            ('fusion_lag_max_s', 'largest lag of the fusion behind the replay (s)'),
            ('tile_writer_done_after_s', 'from the first motion until the tile writer had every image (s)'),
            ('landmark_error_median_m', 'landmark error, median (m)'),
            ('landmark_error_p95_m', 'landmark error, p95 (m)'),
            ('landmark_error_max_m', 'landmark error, max (m)'),
            ('landmark_bound_m', 'bound max(2 GSD, fused 1-sigma) (m)'),
            ('landmark_bound_tiles_m', 'bound max(2 GSD, tiles\' 1-sigma) (m)'),
            ('landmarks_*', 'landmark counts'),
            ('position_sigma_odometry_m', 'fused position 1-sigma, median (m)'),
            ('position_sigma_tiles_m', 'tiles\' position 1-sigma (m)'),
            ('tile_misalignment_px', 'consecutive tiles misaligned, max (px)'),
            ('tile_misalignment_median_px', 'consecutive tiles misaligned, median (px)'),
            ('tile_misalignment_pairs', 'consecutive tile pairs'),
            ('tile_misalignment_patch_p95_px', 'consecutive tiles: worst patch p95 (px)'),
            ('tile_misalignment_translation_max_px', 'consecutive tiles: translation part, max (px)'),
            ('tile_misalignment_rotation_max_mrad', 'consecutive tiles: rotation part, max (mrad)'),
            ('tile_misalignment_scale_max_permille', 'consecutive tiles: scale part, max (per mille)'),
            ('tile_misalignment_spread_median_px', 'consecutive tiles: patch spread, median (px)'),
            ('return_pass_misalignment_max_px', 'other overlapping pairs (return passes) misaligned, max (px)'),
            ('return_pass_misalignment_median_px', 'other overlapping pairs misaligned, median (px)'),
            ('return_pass_misalignment_max_m', 'other overlapping pairs misaligned, max (m)'),
            ('return_pass_misalignment_patch_p95_px', 'other pairs: worst patch p95 (px)'),
            ('return_pass_pairs', 'other overlapping pairs'),
            ('overlap_misalignment_max_px', 'every overlapping pair (consecutive, return passes, crossings) '
                                            'misaligned, max (px)'),
            ('overlap_misalignment_median_px', 'every overlapping pair misaligned, median (px)'),
            ('overlap_pairs', 'overlapping pairs'),
            ('*probe_live_overlap_max_px*', 'archive-rate probe: live tiles, every overlapping pair misaligned, max (px)'),
            ('*probe_live_landmark_p95_m*', 'archive-rate probe: live tiles, landmark error p95 (m)'),
            ('*probe_rate*', 'archive-rate probe: replay rate (x real time)'),
            ('*probe_frames_dropped*', 'archive-rate probe: frames dropped'),
            ('*probe_cpu_ms_per_frame*', 'archive-rate probe: CPU per frame of the bag, per node (ms)'),
            ('*probe_chain_fps*', 'archive-rate probe: chain throughput (frames/s)'),
            ('*probe_peak_rss_mb*', 'archive-rate probe: peak resident memory (MB)'),
            ('*probe_overlap_misalignment_max_px*', 'archive-rate probe: every overlapping pair misaligned, max (px)'),
            ('*probe_landmark_error_p95_m*', 'archive-rate probe: landmark error, p95 (m)'),
            ('*_live_overlap_max_px', 'live tiles: every overlapping pair misaligned, max (px)'),
            ('*_live_landmark_p95_m', 'live tiles: landmark error, p95 (m)'),
            ('*rate_no_drop', 'replay rate reached with no frame dropped (x real time; n/a: every attempt dropped)'),
            ('*cpu_ms_per_frame*', 'CPU per frame of the bag, per node, start-up included (ms)'),
            ('*peak_rss_mb_max', 'peak resident memory of the largest node (MB)'),
            ('*overlap_level_step_max_grey', 'overlapping tiles: mean luma step, max over pairs (grey levels)'),
            ('*overlap_abs_diff_median_grey', 'overlapping tiles: |luma difference| median, pooled (grey levels)'),
            ('overlap_colour_pairs', 'overlapping pairs compared in colour'),
            ('overlap_colour_pixels', 'common pixels compared in colour'),
            ('pose_graph', 'the fusion\'s pose graph ran'),
            ('graph_modes', 'runs: off (without the pose graph), on (with it)'),
            ('analysis_s', 'time to measure the tiles (s)'),
            ('adjust_tiles_s', 'time to adjust (adjust_tiles) and measure the tiles (s)'),
            ('graph_modes_from_previous_run', 'graph modes whose figures are the previous run\'s'),
            ('adjusted_*_with_graph', 'after adjust_tiles, tiles of the run with the graph'),
            ('adjusted_tile_misalignment_px', 'after adjust_tiles: consecutive tiles, max (px; target <= 2)'),
            ('adjusted_tile_misalignment_median_px', 'after adjust_tiles: consecutive tiles, median (px)'),
            ('adjusted_return_pass_misalignment_max_px', 'after adjust_tiles: other pairs, max (px; target <= 2)'),
            ('adjusted_return_pass_misalignment_median_px', 'after adjust_tiles: other pairs, median (px)'),
            ('adjusted_landmark_error_*_m', 'after adjust_tiles: landmark error (m)'),
            ('*_recomposed_overlap_max_px', 'recomposed after the dive from the final pose graph (recompose_tiles): '
                                            'every overlapping pair misaligned, max (px; target <= 1)'),
            ('*_recomposed_landmark_p95_m', 'recomposed after the dive: landmark error, p95 (m; target <= half the '
                                            'live figure)'),
            ('*_recomposed_graph_only_overlap_max_px', 'recomposed at the graph\'s placements only '
                                                       '(--no-image-adjustment): every overlapping pair, max (px)'),
            ('*_recomposed_graph_only_landmark_p95_m', 'recomposed at the graph\'s placements only: landmark error, '
                                                       'p95 (m)'),
            ('recomposed_graph_only_*', 'recomposed at the graph\'s placements only (recompose_tiles '
                                        '--no-image-adjustment)'),
            ('recomposed_image_adjustment_*', 'recompose_tiles\' adjustment of the images to one another: pairs '
                                              'measured, left out, largest cross-pass RMS disagreement before and '
                                              'after (px), largest move (m, rad)'),
            ('*_recomposed_graph_sigma_m', 'recomposed after the dive: the pose graph\'s own radial 1-sigma '
                                           '(sqrt(sigma_E^2 + sigma_N^2)) at the landmarks, median (m)'),
            ('*_recomposed_landmarks_within_graph_sigma', 'recomposed after the dive: landmarks whose error is within '
                                                          'that 1-sigma (0.63 for errors drawn from it)'),
            ('*_recomposed_overlap_*_grey', 'recomposed after the dive: overlapping tiles in colour (grey levels)'),
            ('recomposed_*', 'recomposed after the dive from the final pose graph (recompose_tiles)'),
            ('recompose_tiles_s', 'time to recompose (recompose_tiles) and measure the tiles (s)'),
            ('peak_rss_mb*', 'peak resident memory (MB)'),
            ('cpu_s_*', 'CPU time of the node (s)'),
            ('chain_cpu_s', 'CPU time of the three nodes (s)'),
            ('chain_cpu_cores', 'mean cores used by the chain'),
            ('gsd_m', 'tile pixel size (m)'),
            ('tiles', 'tiles written'),
            ('tile_write_ms_*', 'time to write a tile (ms)'),
            ('load_average_1min', 'machine load average during the run'),
            ('cpu_count', 'cores of the machine'),
            ('run_time_s', 'benchmark wall time (s)'),
        ],
    },
    'web_map.json': {
        'title': 'Live web map (web_map_node)',
        'command': 'devel/lib/exocet_web/bench_web_map --output-dir out/bench [--rate R] [--throughput-rate R] [--clients N] '
                   '[--no-stress]',
        'measures': 'How fast a GeoTIFF tile written by the chain reaches the pages watching the live web map, what '
                    'cutting it into web tiles costs, and whether browsers watching slow the chain down.',
        'data': 'The sample out-and-back dive (`bags/sample_out_and_back.bag`: 435 PAL images, 87 s, four tiles of '
                '150 images), replayed through `replay.launch web:=true`.',
        'method': [
            'Three replays at `rate` on a private ROS master: without any client; with N lightweight clients (Python threads '
            'in the benchmark process, each holding the /events stream as a page does and fetching, of each tile '
            'announced, what a page following the vehicle shows: its web tiles of the finest zoom, where web_map.js '
            'follows, inside a 1280 x 800 window centred on the vehicle\'s last position; a tile version with none '
            'there is counted apart, `tile_versions_out_of_view`); with N clients fetching every web tile announced, '
            'every level (`stress_all_levels`: more than any page asks for).',
            'Latency, for each tile version written (first versions and re-renderings): from the tile writer\'s Tile '
            'message (sent once the GeoTIFF is renamed into place) to a client having received the first "webtiles" '
            'event of that tile at that version or a later one (the node cuts only the newest of versions queued '
            'together; a cut announces its finest level first, then the coarser levels built from it) and fetched the web tiles it asks for (status 200); median, p95 and max over versions and '
            'clients; failed requests by HTTP status or, without an answer, by error. CPU per web tile: '
            'web_map_node\'s user + system time over the web tiles it cut (all levels), in the run without clients. '
            'Chain frames per second: image pairs registered (/mosaic/motion) per wall second between the first and '
            'the last, on two more replays at `throughput_rate` (8x: the chain, not the bag, sets the pace; at 1x '
            'both runs register at the camera\'s 5 frames/s whatever the clients do, `live_chain_fps_*`), with 0 '
            'and N clients; frames dropped: images in the bag, less the first, less the pairs registered; CPU per '
            'frame of each chain node (its user + system time over the pairs registered).',
        ],
        'targets': ['A new tile on the pages within 2 s of being written; the chain\'s frames per second the same '
                    'with 20 clients as with none (within the run-to-run noise).'],
        'figures': [
            ('tile_written_to_announced_ms.*', 'GeoTIFF written -> its announcement received by a client (ms)'),
            ('tile_written_to_served_ms.*', 'GeoTIFF written -> all its web tiles fetched by a client (ms)'),
            ('node_max_cut_latency_ms', 'web_map_node: tile message queued -> its finest level cut and announced, max (ms)'),
            ('cpu_ms_per_web_tile', 'web_map_node CPU per web tile cut (ms)'),
            ('wall_ms_per_web_tile', 'cutting wall time per web tile (ms)'),
            ('chain_fps_*', 'image pairs registered per second, at `throughput_rate`'),
            ('chain_frames_dropped_*', 'frames the chain did not register, at `throughput_rate`'),
            ('chain_cpu_ms_per_frame_*', 'CPU of each chain node per frame, at `throughput_rate` (ms)'),
            ('live_chain_*', 'the same at `rate` (live)'),
            ('throughput_rate', 'replay speed of the chain pace runs'),
            ('images_in_bag', 'camera images in the bag'),
            ('web_tiles_cut', 'web tiles cut (every level)'),
            ('geotiff_tiles_cut', 'GeoTIFF tiles cut'),
            ('client_requests', 'requests of the clients'),
            ('client_errors', 'failed requests of the clients'),
            ('client_error_statuses.*', 'failed requests of the clients by HTTP status, or the error that left no '
             'answer'),
            ('tile_versions_out_of_view', 'tile versions x clients with no web tile in the window of a page '
             'following the vehicle'),
            ('tile_versions_written', 'tile versions written during the replay (first versions and re-renderings)'),
            ('tile_versions_never_served', 'tile versions x clients never fetched whole (a request failed, or the '
             'replay ended first)'),
            ('stress_all_levels.tile_versions_never_served', 'clients fetching every level: tile versions x clients '
             'never fetched whole'),
            ('stress_all_levels.tile_written_to_served_ms.*', 'clients fetching every level: GeoTIFF written -> all '
             'its web tiles fetched by a client (ms)'),
            ('stress_all_levels.tile_written_to_announced_ms.*', 'clients fetching every level: GeoTIFF written -> '
             'its announcement received by a client (ms)'),
            ('stress_all_levels.chain_fps', 'clients fetching every level: image pairs registered per second'),
            ('stress_all_levels.client_*', 'clients fetching every level: their requests, failed requests'),
            ('rate', 'replay speed'),
            ('clients', 'clients in the second and third replays'),
        ],
    },
    'servo.json': {
        'title': 'Intrinsics-free visual servoing, point level',
        'command': 'devel/lib/exocet_servo/bench_servo --output-dir out/bench',
        'measures': 'Final pose error of the intrinsics-free servo (Malis) when the left camera, with other '
                    'intrinsics, is servoed to where the right camera took the reference image; the same for '
                    'ViSP\'s image-based servo on the raw points; the circular acquisition\'s agreement with its '
                    'screw-motion prediction; the rate of one control-law step. `bench_servo_image` fills in the '
                    'image-level figures (`image_loop_*`, `control_rate_hz`).',
        'data': 'A simulated vent-like point object (100 points, 0.3 m, 1 m away), two pinhole cameras with '
                'different intrinsics, start poses 50-100 mm and 5-9 degrees from the goal, 0.5 px image noise '
                '(3 seeds per start) and noise-free runs; the rig transform of the 2D4 report (baseline 0.3 m, pan '
                '18 degrees) for the circle of 20 servoings.',
        'method': [
            'Final error: position (mm) and rotation (deg) of the left camera against the right camera\'s pose at '
            'the reference, mean and max over the runs. The pose bound is the Cramer-Rao bound of the pose from one '
            'image with the same noise, with the intrinsics unknown (the servo\'s case) and known: the servo ends '
            'where the noisy reference puts it, about 1.4 times that bound.',
            'ViSP IBVS: `vpServo` with `vpFeaturePoint`s, fed the right camera\'s reference: it converges to the '
            'pose where the left image looks like the right one, which is the wrong pose when the intrinsics '
            'differ. ViSP\'s tutorial-ibvs-4pts (lambda 0.5) gives the iteration count of a classical servo.',
            'Circle: 20 servoings along the rig-induced circle; prediction error is the largest distance to the '
            'screw-motion prediction, drift the distance between start and end.',
            'Control-law rate: one step (invariant points, interaction matrix, pseudo-inverse) with 200 points, '
            '2000 repetitions.',
        ],
        'targets': [
            'Point level with 0.5 px noise: 0.5 mm / 0.05 deg. The geometry does not allow it: with unknown '
            'intrinsics the depth of a 0.3 m object at 1 m is confounded with the focal length, and the floor '
            'shrinks as 1 / sqrt(points) (`final_pos_err_mm_rms_by_points`). The image-level loop meets its goal '
            'because its points are sub-pixel registered.',
            'Image level: 2 mm / 0.2 deg; control step at least 30 Hz; circle prediction within 1 mm.',
        ],
        'figures': [
            ('final_pos_err_mm', 'invariant servo, 0.5 px noise: position error, mean (mm)'),
            ('final_rot_err_deg', 'invariant servo, 0.5 px noise: rotation error, mean (deg)'),
            ('final_pos_err_mm_max', 'invariant servo, 0.5 px noise: position error, max (mm)'),
            ('final_rot_err_deg_max', 'invariant servo, 0.5 px noise: rotation error, max (deg)'),
            ('iterations', 'invariant servo, 0.5 px noise: iterations, mean'),
            ('final_pos_err_mm_noise_free', 'invariant servo, no noise: position error, max (mm)'),
            ('final_rot_err_deg_noise_free', 'invariant servo, no noise: rotation error, max (deg)'),
            ('iterations_noise_free', 'invariant servo, no noise: iterations, mean'),
            ('final_pos_err_mm_rms_by_points.*', 'position error RMS with this many points (mm)'),
            ('pose_bound_intrinsics_unknown_mm', 'one-image pose bound, intrinsics unknown (mm)'),
            ('pose_bound_intrinsics_unknown_deg', 'one-image pose bound, intrinsics unknown (deg)'),
            ('pose_bound_intrinsics_known_mm', 'one-image pose bound, intrinsics known (mm)'),
            ('pose_bound_intrinsics_known_deg', 'one-image pose bound, intrinsics known (deg)'),
            ('ibvs_final_pos_err_mm', 'ViSP IBVS (current interaction): position error, mean (mm)'),
            ('ibvs_final_rot_err_deg', 'ViSP IBVS (current interaction): rotation error, mean (deg)'),
            ('ibvs_desired_final_pos_err_mm', 'ViSP IBVS (desired interaction): position error, mean (mm)'),
            ('ibvs_desired_final_rot_err_deg', 'ViSP IBVS (desired interaction): rotation error, mean (deg)'),
            ('visp_tutorial_iterations', 'ViSP 4-point tutorial: iterations to |e|^2 < 1e-4'),
            ('trajectory_prediction_err_mm', 'circle, 0.5 px: largest distance to the prediction (mm)'),
            ('trajectory_prediction_err_mm_noise_free', 'circle, no noise: largest distance to the prediction (mm)'),
            ('trajectory_prediction_err_mm_1000_points',
             'circle, 1000 points: largest distance to the prediction (mm)'),
            ('circle_drift_mm', 'circle, 0.5 px: drift after 20 servoings (mm)'),
            ('circle_drift_mm_noise_free', 'circle, no noise: drift after 20 servoings (mm)'),
            ('circle_drift_mm_1000_points', 'circle, 1000 points: drift after 20 servoings (mm)'),
            ('control_law_rate_hz', 'one control-law step, 200 points (Hz)'),
            ('control_law_points', 'points of that step'),
            ('image_loop_pos_err_mm', 'image level (from servo_image.json): position error, mean (mm)'),
            ('image_loop_rot_err_deg', 'image level (from servo_image.json): rotation error, mean (deg)'),
            ('control_rate_hz', 'image level (from servo_image.json): control rate, one core (Hz)'),
        ],
    },
    'servo_image.json': {
        'title': 'Intrinsics-free visual servoing, image level',
        'command': 'devel/lib/exocet_servo/bench_servo_image --output-dir out/bench',
        'measures': 'The servo on rendered images, as servo_node runs it (SIFT matching, KLT tracking, invariant '
                    'law): final pose error, control rate on one core, and the 2D4 report\'s circular acquisition, '
                    'through the simulated arm and free-flying.',
        'data': 'exocet_servo\'s ray-cast textured vent (0.3 m high) on a seabed, rendered at 640x480 for two '
                'cameras with different intrinsics (focal lengths 800 px left, 720 x 725 px right). Four starts '
                '50-100 mm and 5-9 degrees from the goal. The rig transform: baseline 0.3 m, pan 18 degrees. The '
                'simulated 6-DOF arm (reach 1.22 m) with its joint limits.',
        'method': [
            'Image loop: the right camera takes the reference image; the left camera is servoed until convergence; '
            'final error against the right camera\'s pose. `*_without_anchoring`: the same without re-anchoring the '
            'points on the reference image near the goal.',
            'Control rate: tracking, invariant features and law per image, CPU time on one core '
            '(`cv::setNumThreads(1)`); `control_rate_hz_wall` by the wall clock.',
            'Circle through the arm: the feasibility check (inverse kinematics along the poses and the screw paths '
            'between them: reach, joint margins, conditioning) from the default start (`arm_circle_default_*`), a '
            'search for where the vent should stand for the longest feasible circle (`arm_circle_placement_m`, '
            '`arm_circle_start_azimuth_deg`), then the run there. Drift: distance to the predicted circle.',
            'Free-flying circle: 20 servoings (a full circle about the vent\'s axis, radius 0.959 m), each from '
            'where the last ended to where the right camera took its reference; a renderer check first confirms '
            'the chimney is seen textured from every side.',
        ],
        'targets': ['Image level: 2 mm / 0.2 deg from the goal; control rate at least 30 Hz on one core; each '
                    'servoing of the circle within 1 mm of the prediction.'],
        'figures': [
            ('image_loop_pos_err_mm', 'position error, mean of the starts (mm)'),
            ('image_loop_rot_err_deg', 'rotation error, mean of the starts (deg)'),
            ('image_loop_pos_err_mm_max', 'position error, max (mm)'),
            ('image_loop_rot_err_deg_max', 'rotation error, max (deg)'),
            ('image_loop_iterations', 'images per servoing, mean'),
            ('image_loop_converged', 'starts that converged'),
            ('image_loop_runs', 'starts'),
            ('image_loop_*_without_anchoring', 'the same without re-anchoring'),
            ('image_loop_converged_without_anchoring', 'starts that converged without re-anchoring'),
            ('control_rate_hz', 'control rate, CPU time on one core (Hz)'),
            ('control_rate_hz_wall', 'control rate, wall clock (Hz)'),
            ('control_cpu_ms_*', 'CPU time per image (ms)'),
            ('control_wall_ms_*', 'wall time per image (ms)'),
            ('control_points_mean', 'points tracked, mean'),
            ('sift_match_ms_mean', 'SIFT matching, mean (ms)'),
            ('load_average', 'machine load average'),
            ('arm_circle_default_feasible_servoings', 'arm, default start: servoings the check finds feasible'),
            ('arm_circle_default_min_sigma', 'arm, default start: smallest Jacobian singular value predicted'),
            ('arm_circle_default_servoings', 'arm, default start: servoings completed'),
            ('arm_circle_default_status', 'arm, default start: how the run ended'),
            ('arm_circle_default_min_sigma_run', 'arm, default start: smallest singular value in the run'),
            ('arm_circle_default_drift_end_mm', 'arm, default start: drift at the end (mm)'),
            ('arm_circle_placement_m', 'arm: vent placement found [x, y, z] in the arm base (m)'),
            ('arm_circle_start_azimuth_deg', 'arm: start azimuth of that placement (deg)'),
            ('arm_circle_min_sigma', 'arm: smallest singular value predicted there'),
            ('arm_circle_min_joint_margin_rad', 'arm: smallest joint margin predicted there (rad)'),
            ('arm_circle_feasible_servoings', 'arm: servoings feasible there'),
            ('arm_circle_max_feasible_servoings_any_placement', 'arm: most servoings feasible at any placement'),
            ('arm_circle_search_s', 'arm: placement search time (s)'),
            ('arm_circle_servoings', 'arm: servoings completed there'),
            ('arm_circle_status', 'arm: how the run ended'),
            ('arm_circle_images', 'arm: images'),
            ('arm_circle_drift_end_mm', 'arm: distance to the predicted circle at the end (mm)'),
            ('arm_circle_drift_end_deg', 'arm: rotation from the predicted circle at the end (deg)'),
            ('arm_circle_quarter_drift_mm', 'arm: distance to the predicted circle after a quarter circle (mm)'),
            ('arm_circle_quarter_drift_deg', 'arm: rotation from the predicted circle after a quarter circle (deg)'),
            ('arm_circle_min_sigma_run', 'arm: smallest singular value in the run'),
            ('circle_servoings', 'free-flying circle: servoings completed'),
            ('circle_drift_end_mm', 'free-flying circle: drift after the last servoing (mm)'),
            ('circle_drift_end_deg', 'free-flying circle: rotation drift after the last servoing (deg)'),
            ('circle_drift_max_mm', 'free-flying circle: largest drift (mm)'),
            ('circle_closure_mm', 'free-flying circle: distance to the start after the full circle (mm)'),
            ('circle_closure_deg', 'free-flying circle: rotation from the start after the full circle (deg)'),
            ('circle_images', 'free-flying circle: images'),
            ('circle_status', 'free-flying circle: how it ended'),
            ('circle_seconds', 'free-flying circle: wall time (s)'),
            ('circle_renderer_min_chimney_fraction', 'smallest fraction of a view the chimney fills'),
            ('circle_renderer_min_chimney_gradient', 'smallest mean gradient on the chimney (texture check)'),
            ('servoing', 'servoing number'),
            ('drift_mm', 'distance to the predicted circle (mm)'),
            ('drift_deg', 'rotation from the predicted circle (deg)'),
            ('final_pos_err_mm', 'position error at the end (mm)'),
            ('final_rot_err_deg', 'rotation error at the end (deg)'),
            ('initial_pos_mm', 'start position error (mm)'),
            ('initial_rot_deg', 'start rotation error (deg)'),
            ('images', 'images'),
            ('iterations', 'images'),
            ('rematches', 'SIFT re-matchings'),
            ('initial_matches', 'SIFT pairs at the start'),
            ('status', 'how it ended'),
        ],
        'groups': {'circle_per_servoing': 'Free-flying circle, per servoing', 'starts': 'Image loop, per start'},
    },
    'stereo.json': {
        'title': 'Dense stereo (Middlebury)',
        'command': 'devel/lib/exocet_stereo/bench_stereo --output-dir out/bench [--methods ssd,dp,...] '
                   '[--scenes tsukuba,...] [--threads N] [--pm-seed N] [--pm-seeds 1,2,...]',
        'measures': 'Quality and speed of each dense stereo method of `exocet_stereo` on the Middlebury v2 scenes, '
                    'and how PatchMatch\'s result depends on its random seed.',
        'data': 'Middlebury v2 stereo pairs tsukuba, venus, teddy and cones (`../shared/data/middlebury_stereo`), '
                'with their ground-truth disparities and masks.',
        'method': [
            'Bad pixels: percentage of the mask\'s pixels whose disparity differs from the ground truth by more '
            'than 1 px, on the non-occluded (nonocc), all and near-discontinuity (disc) masks, as the Middlebury v2 '
            'evaluation. Integer disparities except PatchMatch where the ground truth is fractional (its Tsukuba '
            'map is rounded, as the published one). One parameter set for all scenes, chosen on these same four '
            'scenes (there is no other ground truth here).',
            'Methods: shiftable-window SSD (ssd), dynamic programming with occlusions (dp), scanline optimisation '
            '(so) and its 8-direction variant (sgm), alpha-expansion graph cuts (gc), Bayesian diffusion (bd), '
            'OpenCV\'s StereoSGBM (sgbm, the baseline) and the project\'s PatchMatch Stereo (pm, Bleyer et al. '
            '2011, with a left-right tolerance of 0.75 px, a final 5x5 median and gradient differences truncated '
            'at 4 grey levels).',
            'Time (ms): best of 3 runs for the fast methods, one run above a second, one thread (`--threads 1`).',
            'PatchMatch draws random planes; one published run is one draw. The seed study (`pm_seeds`) runs pm '
            'from each of `--pm-seeds` (default 1-5; untimed, every core, the result does not depend on the thread '
            'count) and gives the mean and the worst.',
        ],
        'targets': [
            'Graph cuts at most 2 % bad pixels (nonocc) on Tsukuba.',
            'The fastest method at least 20 frames/s on Tsukuba (at most 50 ms).',
            'The best method at or below the published PatchMatch Stereo rates on each scene.',
        ],
        'references': ['PatchMatch Stereo, published non-occluded bad pixels (%): tsukuba 2.09, venus 0.21, teddy '
                       '2.99, cones 2.47 (`../shared/data/middlebury_stereo/reference_patchmatch_badpixels.csv`).'],
        'figures': [
            ('nonocc', 'non-occluded bad pixels (%)'),
            ('all', 'bad pixels, all (%)'),
            ('disc', 'bad pixels near discontinuities (%)'),
            ('ms', 'time, one thread (ms)'),
            ('seeds', 'seeds'),
            ('nonocc_mean', 'mean over the seeds (%)'),
            ('nonocc_max', 'worst seed (%)'),
        ],
        'groups': {'pm_seeds': 'PatchMatch seed study: non-occluded bad pixels (%) per seed'},
    },
    'reconstruction.json': {
        'title': '3D reconstruction',
        'command': 'devel/lib/exocet_stereo/bench_reconstruction --output-dir out/bench --shared-data '
                   '$PWD/../shared/data [--only all|vent]',
        'measures': 'Stereo rig calibration against OpenCV\'s stored result; sparse multi-view reconstruction from '
                    'perturbed poses beside COLMAP; dense reconstruction of a rendered vent scored against its exact '
                    'geometry.',
        'data': 'Calibration: 13 real chessboard pairs 640x480 (`../shared/data/stereo_chessboard`, 9x6 inner '
                'corners, 25 mm squares assumed). Sparse: Middlebury templeSparseRing, 16 real 640x480 views with '
                'exact K R t (`../shared/data/temple_sparse_ring`), starting from poses perturbed by 5 % of the '
                'camera-to-object distance and 3 degrees. Vent: exocet_servo\'s rendered vent (0.3 m high) seen by '
                'ten stereo pairs on a ring 0.6 m around it, baseline 0.15 m, two different known intrinsics, no '
                'image noise.',
        'method': [
            'Calibration: OpenCV `calibrateCamera` + `stereoCalibrate`; RMS reprojection errors and focal lengths, '
            'and their differences to OpenCV\'s stored `intrinsics.yml`.',
            'Sparse: pairs by nearest centres, SIFT matching with an epipolar check from the initial poses, tracks, '
            'triangulation, Ceres bundle adjustment, outlier removal, bundle adjustment. Centre error: after the '
            'best similarity alignment to the true poses, as % of each camera\'s distance to the object; max and '
            'RMS. COLMAP (CPU SIFT, exhaustive matching, incremental mapper with the exact intrinsics held) on '
            'the same 16 images, without a pose prior.',
            'Vent: rectification and dense SGM per pair over the depths of a crop box, depth maps fused into one '
            'cloud (multi-view consistency, 1.5 mm voxels), surface by moving least squares on a 2 mm grid; RMS '
            'distance to the true surface over the chimney and top (points below 5 mm above the seabed left out), '
            'in mm and in % of the vent\'s height; completeness: share of points sampled every 2 mm on the true '
            'chimney with a surface vertex within 3 mm. Optimistic in two ways: no sensor noise, exact rig and '
            'poses.',
        ],
        'targets': ['Vent surface within 0.5 % of the vent\'s height (RMS).'],
        'figures': [
            ('calib_pairs_used', 'chessboard pairs used'),
            ('calib_rms_left_px', 'left camera RMS reprojection error (px)'),
            ('calib_rms_right_px', 'right camera RMS reprojection error (px)'),
            ('calib_rms_stereo_px', 'stereo RMS reprojection error (px)'),
            ('calib_fx_left_px', 'left focal length (px)'),
            ('calib_fx_right_px', 'right focal length (px)'),
            ('calib_*_minus_opencv_px', 'difference to OpenCV\'s stored value (px)'),
            ('calib_baseline_mm', 'baseline (mm, with 25 mm squares)'),
            ('calib_optical_axes_deg', 'angle between the optical axes (deg)'),
            ('calib_time_s', 'calibration time (s)'),
            ('temple_views_registered', 'ours: views registered (of 16)'),
            ('temple_points', 'ours: 3D points'),
            ('temple_observations', 'ours: observations'),
            ('temple_reproj_rms_px', 'ours: reprojection RMS (px)'),
            ('temple_center_err_pct', 'ours: camera centre error after alignment, max (%)'),
            ('temple_center_err_rms_pct', 'ours: camera centre error after alignment, RMS (%)'),
            ('temple_initial_center_err_pct', 'perturbed start: camera centre error, max (%)'),
            ('temple_initial_reproj_rms_px', 'perturbed start: reprojection RMS (px)'),
            ('temple_time_s', 'ours: wall time (s)'),
            ('colmap_status', 'COLMAP: how it ran'),
            ('colmap_usable', 'COLMAP: result usable (1 = yes)'),
            ('colmap_time_s', 'COLMAP: wall time (s)'),
            ('colmap_time_ratio', 'our wall time / COLMAP\'s'),
            ('colmap_views_registered', 'COLMAP: views registered (of 16)'),
            ('colmap_points', 'COLMAP: 3D points'),
            ('colmap_reproj_px', 'COLMAP: reprojection RMS (px)'),
            ('colmap_center_err_pct', 'COLMAP: camera centre error after alignment, max (%)'),
            ('colmap_center_err_rms_pct', 'COLMAP: camera centre error after alignment, RMS (%)'),
            ('vent_pairs', 'vent: stereo pairs'),
            ('vent_points', 'vent: fused cloud points on the chimney'),
            ('vent_rms_pct', 'vent: surface RMS distance (% of the height; target <= 0.5)'),
            ('vent_cloud_rms_pct', 'vent: fused cloud RMS distance (% of the height)'),
            ('vent_surface_rms_mm', 'vent: surface RMS distance (mm)'),
            ('vent_cloud_rms_mm', 'vent: fused cloud RMS distance (mm)'),
            ('vent_box_rms_pct', 'vent: surface RMS distance, whole crop box (%)'),
            ('vent_cloud_box_rms_pct', 'vent: cloud RMS distance, whole crop box (%)'),
            ('vent_box_points', 'vent: cloud points in the crop box'),
            ('vent_completeness_pct', 'vent: completeness (%)'),
            ('vent_surface_vertices', 'vent: surface vertices'),
            ('vent_surface_triangles', 'vent: surface triangles'),
            ('vent_object_size_m', 'vent: height (m)'),
            ('vent_baseline_m', 'vent: rig baseline (m)'),
            ('vent_method', 'vent: dense stereo method'),
            ('vent_*seconds', 'vent: time (s)'),
        ],
    },
    'soak.json': {
        'title': 'Soak: an hour-long dive through the live chain',
        'command': 'make soak (tools/run-soak.sh: devel/lib/exocet_mosaic/soak_dive --output-dir out/bench [--rate R] '
                   '[--attempts N] [--no-web])',
        'measures': 'Whether the live chain holds a dive of an hour and more: frames dropped at the highest replay '
                    'rate, each node\'s resident memory over the dive (what grows with the dive is bounded or '
                    'written out), CPU per frame from the start to the end, tiles written and their landmark error at '
                    'the start and at the end.',
        'data': 'config/dives/soak_pal.yaml rendered once into out/bench/cache/soak_pal.bag: PAL (720x576) at 10 '
                'frames/s, a 25-line lawnmower of 72 m lines 1.6 m apart at 2.5 m altitude over a flat seabed (each '
                'line overlaps its neighbours: the pose graph finds loops all dive long), USBL 0.5 m at 1 Hz, the '
                'heading of a fibre-optic gyro (0.2 deg/h, as on a work-class ROV), 40 checker landmarks along the '
                'track.',
        'method': [
            'The whole chain of replay.launch (registration, fusion with its pose graph and live loop closure, tile '
            'writer, web map) on a private ROS master, the bag played at the rate tried first (8x), then slower '
            'after a drop. Frames dropped as bench_tiles counts them; a rate counts as without drop only when the '
            'fusion did not reset either (its resets and late inputs dropped, and the web map\'s longest queue, from '
            'their /diagnostics).',
            'Every 2 s of wall time each node\'s resident memory (VmRSS) and CPU time (user + system) are sampled '
            'against the dive time the registration has reached. Memory slope: least-squares line through the '
            'samples from the warm-up (10 minutes of dive) to the last frame, in MB per 10 minutes of dive (the '
            'samples after it, when the nodes finish and free what they held, left out). Floor slope: the same line '
            'through the lowest sample of each 5 minutes, what a node keeps between its bursts of work (tiles drawn '
            'again, loops verified). Heap slope (fusion and tile writer): the same line through the memory their heap '
            'holds, as each reports it on /diagnostics (the statistics of jemalloc, which the chain\'s nodes run '
            'on), apart from the free pages the allocator keeps. '
            'CPU per frame: the CPU time over the frames registered, per 10-minute stretch of the dive.',
            'Landmarks: the checker targets found in the tiles made of the first and of the last 10 minutes of the '
            'dive, their error against the simulator\'s truth.',
        ],
        'targets': ['No frame dropped; each node\'s memory slope after the warm-up under 1 MB per 10 minutes of '
                    'dive (issue 22).'],
        'omit': ['attempts', 'nodes.*.rss_mb_series', 'nodes.*.heap_in_use_mb_series',
                 'nodes.*.cpu_ms_per_frame_by_stretch', 'registration_lag_s',
                 'fusion_lag_s', 'tile_writer_*'],
        'groups': {'nodes': 'per node'},
        'figures': [
            ('dive_hours', 'length of the dive (h)'),
            ('frames', 'images in the bag'),
            ('rate', 'replay rate (times real time)'),
            ('rate_no_drop', 'replay rate reached with no frame dropped'),
            ('frames_dropped*', 'frames dropped'),
            ('chain_fps', 'frames per second through the chain'),
            ('rss_slope_mb_per_10min_max', 'largest memory slope of a node after the warm-up (MB per 10 min of dive)'),
            ('rss_slope_mb_per_10min', 'memory slope after the warm-up (MB per 10 min of dive)'),
            ('rss_floor_slope_mb_per_10min_max', 'largest slope of a node\'s lowest memory per 5 min (MB per 10 min)'),
            ('rss_floor_slope_mb_per_10min', 'slope of the lowest memory per 5 min of dive (MB per 10 min of dive)'),
            ('heap_in_use_slope_mb_per_10min', 'slope of the memory the heap holds, after the warm-up (MB per 10 min)'),
            ('heap_in_use_floor_slope_mb_per_10min', 'slope of the heap\'s lowest per 5 min of dive (MB per 10 min)'),
            ('heap_in_use_mb_max', 'most memory the heap held (MB)'),
            ('rss_mb_at_warm_up_end', 'resident memory at the end of the warm-up (MB)'),
            ('rss_mb_at_end', 'resident memory at the end of the dive (MB)'),
            ('rss_mb_max', 'peak resident memory (MB)'),
            ('cpu_ms_per_frame_first_stretch', 'CPU per frame, first 10 minutes of dive (ms)'),
            ('cpu_ms_per_frame_last_stretch', 'CPU per frame, last 10 minutes of dive (ms)'),
            ('peak_rss_mb_*', 'peak resident memory (MB)'),
            ('cpu_s_*', 'CPU time over the replay (s)'),
            ('tiles', 'GeoTIFF tiles written'),
            ('landmark_error_start_*', 'landmark error in the tiles of the first 10 minutes (m)'),
            ('landmark_error_end_*', 'landmark error in the tiles of the last 10 minutes (m)'),
            ('landmark_error_p95_m', 'landmark error p95, whole dive (m)'),
            ('landmarks_*', 'landmarks found / expected'),
            ('replay_wall_s', 'wall time of the replay (s)'),
            ('fusion_resets', 'resets of the fusion (filter, graph and tracks started again)'),
            ('fusion_late_inputs_dropped', 'inputs the fusion dropped as late'),
            ('web_map_queue_length_max', 'web map: longest queue of GeoTIFFs waiting to be cut'),
            ('web_map_max_cut_latency_ms', 'web map: tile message queued -> its finest level cut and announced, max (ms)'),
        ],
    },
    'reliability.json': {
        'title': 'Reliability: faults survived',
        'command': 'rostest exocet_system_tests node_kill_replay.test; the same for bad_recordings_replay.test and '
                   'truncated_bag_replay.test; rostest exocet_mosaic tile_writer_disk_full.test (make test runs them); '
                   'tools/multihost-test.sh (root); make soak (soak_* keys). Each merges its keys into the file',
        'measures': 'Which faults the chain survives: nodes killed mid-dive, a full output disk, bad recordings, a '
                    'degraded link between the vehicle and the surface, a dive of an hour.',
        'data': 'The sample out-and-back dive (PAL, 87 s) replayed at 2x (kills), 3x (bad recordings), 4x (truncated '
                'bag); synthetic frames for the disk-full test.',
        'method': [
            'Kills: the registration, the tile writer, the fusion, the trajectory logger and the web map are each '
            'killed twice with SIGKILL during the replay; a kill is survived when the node is running again '
            '(respawned) and its output goes on (the web map: serving again on the same port, and at the end every '
            'final tile cut into the web site). Tiles lost: tile indices missing or tiles GDAL cannot read at the '
            'end. Frames lost per kill: what the restarted tile writer reports its killed instance held and had not '
            'written.',
            'Disk full: the output folder (a 16 MB tmpfs) is filled twice while mosaics close, then freed; an episode '
            'is survived when writing resumes, no index is skipped and every tile written before is unchanged.',
            'Bad recordings: corrupt JPEGs, images of another size, NaN and backwards navigation, duplicated stamps, a '
            'camera_info that changes, a truncated bag; each survived when it is logged (throttled) and counted on '
            '/diagnostics, no node restarts and the rest of the dive is fused and tiled.',
        ],
        'targets': ['Every kill, disk-full episode and bad recording survived; tiles lost 0; soak: no frame dropped, '
                    'each node\'s memory slope under 1 MB per 10 minutes of dive.'],
        'figures': [
            ('kills_tried', 'SIGKILLs of a node of the chain'),
            ('kills_survived', 'of them, the node respawned and its output went on'),
            ('tiles_lost', 'tile indices missing or unreadable after the kills'),
            ('frames_lost_per_kill_max', 'largest number of frames lost by one tile writer kill'),
            ('disk_full_survived', 'disk-full episodes survived (of 2)'),
            ('bad_recordings_tried', 'bad recordings replayed'),
            ('bad_recordings_survived', 'of them, survived'),
            ('soak_dive_hours', 'make soak: hours of dive replayed'),
            ('soak_rss_slope_mb_per_10min_max', 'make soak: largest memory slope of a node (MB per 10 min of dive)'),
            ('soak_rate_no_drop', 'make soak: replay rate with no frame dropped'),
            ('soak_frames_dropped', 'make soak: frames dropped'),
            ('multihost_frames_delivered_fraction', 'tools/multihost-test.sh: frames delivered over the degraded link'),
            ('multihost_recovery_s', 'tools/multihost-test.sh: from the link back to the first frame received '
             'after it (s)'),
        ],
    },
}

WITHOUT_GRAPH_SUFFIX = '_without_graph'  # a figure of a run without the pose graph: the meaning of the plain name
MAX_INLINE_ITEMS = 12  # longer lists of numbers are summarised (the JSON file has them all)
MAX_RECORD_ROWS = 40   # longer lists of records are summarised


class BadArgument(Exception):
    pass


# ---------------------------------------------------------------------------------------------------------------
# Values.

def is_scalar(v):
    return v is None or isinstance(v, (bool, int, float, str))


def fmt(v):
    """A value as table text: integers as they are, other numbers with 4 significant digits."""
    if v is None:
        return 'n/a'
    if isinstance(v, bool):
        return 'yes' if v else 'no'
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            return 'n/a'
        if v.is_integer() and abs(v) < 1e12:
            return str(int(v))
        if abs(v) >= 1000:
            return '%.0f' % v
        return '%.4g' % v
    if isinstance(v, str):
        return cell(v)
    if isinstance(v, list):
        if all(is_scalar(x) for x in v):
            if len(v) > MAX_INLINE_ITEMS:
                return '[%s, ...] (%d values)' % (', '.join(fmt(x) for x in v[:6]), len(v))
            return '[' + ', '.join(fmt(x) for x in v) + ']'
        return '(%d records)' % len(v)
    if isinstance(v, dict):
        return '(%d entries)' % len(v)
    return cell(str(v))


def cell(text):
    return str(text).replace('|', '\\|').replace('\n', ' ')


def flatten(value, prefix, omit, out):
    """(dotted key, value) pairs: nested objects flattened; lists kept whole (fmt summarises them)."""
    if isinstance(value, dict):
        for k in value:
            key = '%s.%s' % (prefix, k) if prefix else str(k)
            if any(fnmatch.fnmatchcase(key, p) for p in omit):
                continue
            flatten(value[k], key, omit, out)
    else:
        out.append((prefix, value))
    return out


def meaning(key, figures):
    if key.endswith(WITHOUT_GRAPH_SUFFIX):  # bench_tiles: a figure of the run without the pose graph
        text = meaning(key[:-len(WITHOUT_GRAPH_SUFFIX)], figures)
        return text + ' (without the pose graph)' if text else ''
    for pattern, text in figures:
        if fnmatch.fnmatchcase(key, pattern):
            return text
    return ''


# ---------------------------------------------------------------------------------------------------------------
# Tables.

def table(header, rows):
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    lines += ['| ' + ' | '.join(r) + ' |' for r in rows]
    return lines


def is_record_group(value):
    """A dict of two or more dicts (one record each, e.g. per dive or per scene)."""
    return (isinstance(value, dict) and len(value) >= 2 and
            all(isinstance(v, dict) for v in value.values()))


def strip_omit(omit, key, member):
    """The omit patterns that apply inside `key`.`member`, relative to it."""
    out = []
    for p in omit:
        for head in ('%s.*.' % key, '%s.%s.' % (key, member)):
            if p.startswith(head):
                out.append(p[len(head):])
    return out


def records_of_group(value, omit, key):
    return {m: flatten(v, '', strip_omit(omit, key, m), []) for m, v in value.items()}


def render_group(key, value, desc, omit):
    """A dict of records: rows = members and columns = leaf keys, or transposed when there are few members and
    many leaf keys (e.g. the PAL and HD dives side by side)."""
    records = records_of_group(value, omit, key)
    members = list(records)
    leaves = []
    for m in members:
        for k, _ in records[m]:
            if k not in leaves:
                leaves.append(k)
    values = {m: dict(records[m]) for m in members}
    caption = desc.get('groups', {}).get(key, key)
    figures = desc.get('figures', [])
    lines = ['#### %s (`%s`)' % (caption, key), '']
    if len(members) <= 6 and len(leaves) > len(members):
        rows = [['`%s`' % leaf] + [fmt(values[m].get(leaf)) if leaf in values[m] else '' for m in members] +
                [cell(meaning(leaf, figures))] for leaf in leaves]
        lines += table(['figure'] + [cell(m) for m in members] + ['meaning'], rows)
    else:
        rows = [[cell(m)] + [fmt(values[m].get(leaf)) if leaf in values[m] else '' for leaf in leaves]
                for m in members]
        lines += table([cell(key)] + ['%s' % cell(leaf) for leaf in leaves], rows)
        explained = [(leaf, meaning(leaf, figures)) for leaf in leaves if meaning(leaf, figures)]
        if explained:
            lines += ['', '; '.join('%s: %s' % (cell(leaf), cell(text)) for leaf, text in explained) + '.']
    return lines + ['']


def render_records(key, items, desc):
    """A list of records (one row each)."""
    caption = desc.get('groups', {}).get(key, key)
    lines = ['#### %s (`%s`)' % (caption, key), '']
    if len(items) > MAX_RECORD_ROWS:
        return lines + ['%d records: see the JSON file.' % len(items), '']
    flat = [dict(flatten(item, '', [], [])) if isinstance(item, dict) else {'value': item} for item in items]
    columns = []
    for f in flat:
        for k in f:
            if k not in columns:
                columns.append(k)
    lines += table([cell(c) for c in columns], [[fmt(f[c]) if c in f else '' for c in columns] for f in flat])
    figures = desc.get('figures', [])
    explained = [(c, meaning(c, figures)) for c in columns if meaning(c, figures)]
    if explained:
        lines += ['', '; '.join('%s: %s' % (cell(c), cell(text)) for c, text in explained) + '.']
    return lines + ['']


def matrix_families(groups, omit):
    """Record groups with the same members and the same scalar leaves (e.g. one per stereo method, each holding
    the same scenes): shown as one table per leaf, rows = groups, columns = members."""
    shapes = {}
    for key, value in groups.items():
        records = records_of_group(value, omit, key)
        if not all(all(is_scalar(v) for _, v in r) for r in records.values()):
            continue
        members = tuple(records)
        leaves = []  # in the order of the file
        for r in records.values():
            leaves += [k for k, _ in r if k not in leaves]
        if len(leaves) > 6:
            continue
        shape = (members, frozenset(leaves))
        if shape not in shapes:
            shapes[shape] = (tuple(leaves), [])
        shapes[shape][1].append(key)
    return {(members, leaves): keys for (members, _), (leaves, keys) in shapes.items() if len(keys) >= 2}


def render_figures(data, desc):
    """The tables of one JSON document."""
    omit = desc.get('omit', [])
    figures = desc.get('figures', [])
    lines = []
    scalars, groups, record_lists = [], {}, {}
    for key, value in data.items():
        if str(key).startswith('_') or any(fnmatch.fnmatchcase(key, p) for p in omit):
            continue
        if is_record_group(value):
            groups[key] = value
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            record_lists[key] = value
        else:
            flatten(value, key, omit, scalars)
    if scalars:
        lines += table(['figure', 'value', 'meaning'],
                       [['`%s`' % cell(k), fmt(v), cell(meaning(k, figures))] for k, v in scalars])
        lines.append('')
    in_family = set()
    for (members, leaves), keys in matrix_families(groups, omit).items():
        in_family.update(keys)
        for leaf in leaves:
            text = meaning(leaf, figures)
            heading = cell(text[:1].upper() + text[1:]) if text else cell(leaf)
            lines += ['#### %s (`%s`)' % (heading, leaf), '']
            rows = []
            for key in keys:
                values = dict(flatten(groups[key], '', [], []))
                rows.append(['`%s`' % cell(key)] + [fmt(values['%s.%s' % (m, leaf)]) if '%s.%s' % (m, leaf) in values
                                                    else '' for m in members])
            lines += table([''] + [cell(m) for m in members], rows)
            lines.append('')
    for key, value in groups.items():
        if key not in in_family:
            lines += render_group(key, value, desc, omit)
    for key, items in record_lists.items():
        lines += render_records(key, items, desc)
    return lines


# ---------------------------------------------------------------------------------------------------------------
# The page.

def measured_on(path, data):
    stated = data.get('_measured_on') if isinstance(data, dict) else None
    if isinstance(stated, str) and stated:
        return stated
    stamp = datetime.datetime.fromtimestamp(os.path.getmtime(path), datetime.timezone.utc)
    return stamp.strftime('%Y-%m-%d %H:%M UTC') + ' (date of the file)'


def section(name, path, desc):
    """Lines of one benchmark's section, and the error if its file could not be read."""
    title = desc.get('title', name[:-len('.json')].replace('_', ' ').capitalize()) if desc else \
        name[:-len('.json')].replace('_', ' ').capitalize()
    lines = ['## %s' % title, '', 'File: `%s`.' % name]
    if desc:
        if desc.get('command'):
            lines[-1] += ' Run alone: `%s`.' % desc['command']
        lines += ['', '**What it measures.** ' + desc['measures'], '', '**Data.** ' + desc['data'], '',
                  '**Method.**', '']
        lines += ['- ' + p for p in desc['method']]
        lines += ['', '**Targets.**', '']
        lines += ['- ' + t for t in desc['targets']]
        for r in desc.get('references', []):
            lines += ['', '**Reference.** ' + r]
    lines.append('')
    if not os.path.exists(path):
        return lines + ['Not run: there is no `%s` (run `make bench`).' % name, ''], None
    try:
        with open(path) as f:
            data = json.load(f)
        if not isinstance(data, dict):
            raise ValueError('the file holds a %s, not a JSON object' % type(data).__name__)
    except (OSError, ValueError) as e:
        return lines + ['Could not be read: %s.' % cell(e), ''], '%s: %s' % (path, e)
    if not desc:
        lines += ['No description of this benchmark yet (add one to BENCHMARKS in '
                  '`tools/make-benchmarks-doc.py`); its figures as written:', '']
    lines += ['### Figures', '', '*Measured on: %s.*' % cell(measured_on(path, data)), '']
    note = data.get('_note')
    if isinstance(note, str) and note:
        lines += ['*Note: %s*' % cell(note), '']
    return lines + render_figures(data, desc or {}), None


def build(bench_dir):
    files = sorted(os.path.basename(p) for p in glob.glob(os.path.join(bench_dir, '*.json')))
    names = list(BENCHMARKS) + [f for f in files if f not in BENCHMARKS]
    lines = [
        '# Benchmarks',
        '',
        '<!-- Generated by tools/make-benchmarks-doc.py from the benchmarks\' JSON files: do not edit by hand. The '
        'descriptions are in the script. -->',
        '',
        '`make bench` runs every benchmark (`tools/run-bench.sh`: the executables `bench_*` of the workspace), each '
        'writing `out/bench/<name>.json`, then writes this page from those files. Speeds and memory depend on the '
        'machine and on what else runs on it: each section gives its date, and the method says whether a time is '
        'wall-clock or CPU. Accuracy figures do not depend on the machine.',
        '',
    ]
    lines += ['- [%s](#%s)' % (BENCHMARKS.get(n, {}).get('title', n), anchor(BENCHMARKS.get(n, {}).get('title', n)))
              for n in names if n in BENCHMARKS or n in files]
    lines.append('')
    errors = []
    for name in names:
        body, error = section(name, os.path.join(bench_dir, name), BENCHMARKS.get(name))
        lines += body
        if error:
            errors.append(error)
    while lines and lines[-1] == '':
        lines.pop()
    return '\n'.join(lines) + '\n', errors


def anchor(title):
    """GitHub's heading anchor."""
    text = ''.join(c for c in title.lower() if c.isalnum() or c in ' -_')
    return text.replace(' ', '-')


def write_atomically(path, text):
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix='.' + os.path.basename(path) + '.', suffix='.partial', dir=folder)
    try:
        with os.fdopen(fd, 'w') as f:
            f.write(text)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def parse_arguments(argv):
    parser = argparse.ArgumentParser(
        prog='make-benchmarks-doc.py',
        description='Writes the benchmarks page (Markdown) from the JSON files that make bench writes.')
    parser.add_argument('--bench-dir', default='out/bench', help='folder of the *.json files (default out/bench)')
    parser.add_argument('--output', default='docs/benchmarks.md', help='page to write (default docs/benchmarks.md)')
    args = parser.parse_args(argv)  # exits 2 with a message on an unknown or incomplete option
    if not os.path.isdir(args.bench_dir):
        raise BadArgument('--bench-dir %s is not a folder (make bench writes out/bench)' % args.bench_dir)
    if not args.output or os.path.isdir(args.output):
        raise BadArgument('--output %r must name a file, not a folder' % args.output)
    return args


def main(argv):
    try:
        args = parse_arguments(argv)
    except BadArgument as e:
        print('make-benchmarks-doc: %s' % e, file=sys.stderr)
        return 2
    text, errors = build(args.bench_dir)
    try:
        write_atomically(args.output, text)
    except OSError as e:
        print('make-benchmarks-doc: cannot write %s: %s' % (args.output, e), file=sys.stderr)
        return 1
    for error in errors:
        print('make-benchmarks-doc: could not read %s' % error, file=sys.stderr)
    print('make-benchmarks-doc: wrote %s' % args.output)
    return 1 if errors else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
