"""slam_lcd.frontend"""
