"""slam_lcd.io"""
