"""slam_lcd.vocab"""
