"""slam_lcd.lcd"""
