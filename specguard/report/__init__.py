"""What runs leave for people: session reports, learning-curve figures, GIFs, the reproduction document."""
