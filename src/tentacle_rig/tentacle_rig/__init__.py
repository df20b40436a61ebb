"""The rig as a whole: process table and bringup, recorder, the lab facade, the navigation demo."""
