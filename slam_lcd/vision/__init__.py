"""slam_lcd.vision: the geometry the front end and loop verification share: camera model, undistortion,
back-projection, PnP, epipolar RANSAC, grey conversion.
May import: numpy, scipy, cv2 and the base modules (types, errors, geometry); nothing else.
"""
