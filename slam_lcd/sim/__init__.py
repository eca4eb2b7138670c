"""slam_lcd.sim"""
