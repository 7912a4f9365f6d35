"""Camera motion and timing: motion blur, rolling shutter, stereo desynchronisation."""
