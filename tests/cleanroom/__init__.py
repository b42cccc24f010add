"""Clean-room data generators: written from the physics (the papers, textbook forms) and the
format specification alone, by sessions that had not read the implementation they test."""
