"""Does the layout move change results? The demo-folder comparer (compare_demo)."""
