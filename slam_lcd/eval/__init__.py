"""slam_lcd.eval"""
