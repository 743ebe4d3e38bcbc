"""Files: IMU readers and writers, column layouts, aiding files (text, NMEA), resampling, provenance, atomic report
folders, HTML pages and progress bars."""
