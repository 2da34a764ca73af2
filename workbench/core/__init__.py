"""Pure numerics: numpy and scipy only, arrays in and arrays out, mm units."""
