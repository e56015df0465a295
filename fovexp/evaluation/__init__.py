"""The paper's analyses of outputs (section 6) and its stereo extension (section 6.4), each a
module on the enhancer's public API (``fovexp``; docs/API.md):

========================  ======================================================  ==========
module                    what                                                     paper
========================  ======================================================  ==========
:mod:`.spectra`           power spectra of the outputs per eccentricity ring,      6.1
                          relative to full resolution, T_L and T_H marked
:mod:`.fovvdp`            FovVDP JOD of each method against full resolution,       6.1
                          paired t-tests (the optional ``[fovvdp]`` extra)
:mod:`.temporal`          mean inter-frame SSIM per condition, temporal slices,    6.2
                          the re-seeded-impulses control
:mod:`.compression`       JPEG (quality 90) sizes of foveated frames at the        6.3
                          participants' blur-rates, contrast against ours
:mod:`.stereo`            noise synthesised for the left eye and forward-warped    6.4
                          to the right by disparity; red-cyan anaglyph
========================  ======================================================  ==========

Each writes a CSV, a figure (PNG) and a short Markdown note (:mod:`.outputs`). The command line
(``fovexp evaluate ...``, ``fovexp stereo``) is :mod:`.cli`, which only parses. Nothing here
imports the experiment runner (``tests/test_layers.py``).
"""
