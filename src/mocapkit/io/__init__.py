"""File formats. Readers convert units on read (SI inside); no maths here."""
