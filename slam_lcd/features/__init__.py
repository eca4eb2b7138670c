"""slam_lcd.features"""
