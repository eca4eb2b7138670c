"""slam_lcd.backend"""
