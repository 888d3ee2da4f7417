"""Images and videos of saved states, made in worker processes; no dataset file is read or written here."""
