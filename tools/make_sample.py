"""
Render the photo-like sample under ``samples/`` (run from the repository root).

The sample is what a newcomer tries ``pattern-locator detect`` on: a card of
the shipped building map (floor 1, room 3, card 2) on a grey wall, seen
2.0 m away and 35 degrees off its normal through a lens with barrel
distortion, under warm, uneven light with defocus, sensor noise and JPEG
compression. ``samples/sample_truth.yaml`` holds the exact pose it was
rendered with.

    .venv/bin/python tools/make_sample.py
"""

from pathlib import Path

import cv2
import numpy as np
import yaml

from pattern_locator.card.pattern import load_pattern_config
from pattern_locator.localization.building import load_building
from pattern_locator.sim.render import (card_pose_facing, CardPlacement, DotCardTexture,
                                        render_scene, RenderOptions)
from pattern_locator.vision.camera import CameraModel, save_camera

OUT = Path('samples')


def main() -> None:
    pattern = load_pattern_config()
    card = load_building().card((1, 3, 2))
    camera = CameraModel.from_fov(640, 480, 48.0, D=[-0.18, 0.05, 0.0005, -0.0003, 0.0],
                                   name='sample_camera')
    T_camera_card = card_pose_facing(2.0, 35.0, 250.0, roll_deg=4.0, offset_px=(60.0, -35.0),
                                     camera=camera)
    options = RenderOptions(gain=0.8, colour_cast=(1.12, 1.0, 0.82), gradient=0.25,
                            gradient_angle_deg=30.0, ambient=0.02, defocus_sigma_px=0.7,
                            shot_noise=0.01, noise_sigma=1.5,
                            background='wall', seed=7)
    result = render_scene(camera, [CardPlacement(T_camera_card,
                                                 DotCardTexture(pattern, card.code))], options)
    OUT.mkdir(exist_ok=True)
    # Compressed once, as a camera or phone would.
    cv2.imwrite(str(OUT / 'card_on_wall.jpg'), result.image, [cv2.IMWRITE_JPEG_QUALITY, 88])
    save_camera(camera, OUT / 'camera.yaml')
    position = T_camera_card.inverse().t
    truth = {'card': {'code': str(card.code), 'floor': 1, 'room': 3, 'pattern': 2},
             'camera_in_pattern_m': [round(float(v), 4) for v in position],
             'T_camera_pattern': np.round(T_camera_card.matrix(), 6).tolist()}
    (OUT / 'sample_truth.yaml').write_text(yaml.safe_dump(truth, sort_keys=False))
    print(f'wrote {OUT}/card_on_wall.jpg, camera.yaml, sample_truth.yaml')


if __name__ == '__main__':
    main()
