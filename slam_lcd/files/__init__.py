"""Files every stage writes or reads the same way: atomic writes and the clash rule, one image file read
with one-line errors (folders of them: :mod:`slam_lcd.io.image_folder`), the sha256 of a file."""
