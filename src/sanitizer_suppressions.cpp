// Sanitizer suppressions, each scoped to a system library (oneTBB; GDAL under OpenCV's image reading) and
// given with its reason (DEVELOPERS.md § Sanitizers). In sanitizer builds CMake links this object
// into every executable (the `loopgate` binary, every test and benchmark), so they hold for a program run by
// hand as well as under ctest, whether or not it runs the pipeline: io tests decode images too.

#if defined(__SANITIZE_THREAD__)
// ThreadSanitizer builds: oneTBB comes from an uninstrumented system library, so the synchronisation of
// its scheduler (task hand-over, small-object pool reuse, the end of wait_for_all) is invisible and its
// header-inlined internals show up as races. Only races whose top frame is inside a oneTBB header are
// suppressed; our node bodies make their hand-overs explicit (FrameRecord::acquire/release, one mutex
// per serial stage) and stay checked.
extern "C" const char* __tsan_default_suppressions() {
  // race_top: only reports whose top frame lies in a oneTBB header; and the publication of a freshly
  // constructed node's aggregator (exact inlined frame name) to the worker that TBB spawns at make_edge.
  // The partitioner internals of tbb::parallel_for (tree nodes on the spawning thread's stack, folded by the
  // thieves) are joined by the library's wait, invisible too.
  return "race_top:/usr/include/oneapi/tbb/\n"
         "race:^aggregator_generic$\n"
         // the same publication when the constructor is reported with its qualified name (queue_node's
         // buffer aggregator, built by the calling thread inside the arena, read by the forward task)
         "race:tbb::detail::d1::aggregator_generic<\n"
         "race:tbb::detail::d1::fold_tree\n"
         "race:tbb::detail::d1::tree_node\n"
         "race:tbb::detail::d1::node::node\n"
         "race:check_being_stolen\n"
         "race:mark_task_stolen\n"
         "race:tbb::detail::d1::task_group_context\n"
         // OpenCV's image reading goes through GDAL, whose own mutexes TSan sees taken in both orders
         // within one thread (a potential-deadlock report inside libgdal, not in our code).
         "deadlock:libgdal.so\n"
         // A task's read of the parallel_for body object TBB copied on the spawning thread (two pointers);
         // everything after it goes through the body's explicit hand-over (parallel_handoff.hpp).
         "race_top:parallel_handoff.hpp\n";
}

// The suppressions above that name a oneTBB function (fold_tree, tree_node, ...) match a frame anywhere in
// either access's stack, so TSan must still hold the earlier access's stack when it reports. With its default
// history (history_size=3, the last 256K memory accesses per thread; the runtime's help text says 2, its
// "Current Value" 3) a busy TBB worker's stack was often gone ("[failed to restore the stack]") and the
// report stood: the flaky one in PipelineGatedMode, the helper that finished a tbb::parallel_for last
// decrementing the loop's root wait node on the spawner's stack (fold_tree), which the spawner later reused
// (docs/reliability.md). The largest history (7: the last 4M accesses per thread) keeps it. TSAN_OPTIONS
// given at run time still win.
extern "C" const char* __tsan_default_options() {
  return "history_size=7";
}
#endif

#if defined(__SANITIZE_ADDRESS__)
// AddressSanitizer builds (LeakSanitizer): oneTBB's observer registration (tbb::task_scheduler_observer::
// observe, called by WorkerExitObserver in run_resources.hpp) allocates a 40-byte list node inside the
// uninstrumented library that the library frees lazily, on its own thread's schedule; under load the process
// can end first and LSan reports it (intermittently, in SeqSLAM runs, aborting the run). Only allocations
// made inside that oneTBB function are exempt; every other leak is reported.
extern "C" const char* __lsan_default_suppressions() {
  return "leak:tbb::detail::r1::observe\n";
}
#endif
