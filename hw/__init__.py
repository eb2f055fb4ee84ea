"""Hardware adapters: instrument protocols, transports, serial drivers, acquisition runner."""
